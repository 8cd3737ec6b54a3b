#!/usr/bin/env python3
"""Writes the capture behind BENCHMARKS.md's learner bound: the learner's worst case,
every register heard often enough to fill its history.

    python3 benches/learn_wide.py OUT.pcap [BLOCKS] [POLLS]

Classic pcap, link type 147 (USER0), one packet per RTU frame. BLOCKS (default 700) blocks of
120 holding registers (FC03, MAP v1.1b3 §6.3), 350 per unit from unit 1 on, each polled POLLS
times (default 100), every value new each poll: 84 000 registers, each with a full history.
"""
import random
import struct
import sys

TABLE = []
for i in range(256):
    c = i
    for _ in range(8):
        c = (c >> 1) ^ 0xA001 if c & 1 else c >> 1
    TABLE.append(c)


def crc(data):
    c = 0xFFFF
    for b in data:
        c = (c >> 8) ^ TABLE[(c ^ b) & 0xFF]
    return struct.pack("<H", c)


def main():
    out, blocks = sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 700
    polls = int(sys.argv[3]) if len(sys.argv) > 3 else 100
    rng = random.Random(39)
    t = 1_700_000_000 * 1_000_000
    with open(out, "wb") as f:
        # Magic, version 2.4, zone 0, sigfigs 0, snaplen 65535, link type 147.
        f.write(struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 65535, 147))

        def rec(frame):
            f.write(struct.pack("<IIII", t // 1_000_000, t % 1_000_000, len(frame), len(frame)) + frame)

        for _ in range(polls):
            for b in range(blocks):
                unit, first = 1 + b // 350, (b % 350) * 120
                q = bytes([unit, 3]) + struct.pack(">HH", first, 120)
                rec(q + crc(q))
                t += 6000
                values = bytes(rng.getrandbits(8) for _ in range(240))
                a = bytes([unit, 3, 240]) + values
                rec(a + crc(a))
                t += 30000


main()
