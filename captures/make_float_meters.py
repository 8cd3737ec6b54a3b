#!/usr/bin/env python3
"""Writes the frame lists of two float meters shaped after the recordings issue 40 describes
(recordings kept outside this repository; no public recording of these shapes could be found
to license, so the frames are made from the shapes the issue gives, byte for byte where it
gives bytes). Deterministic (a fixed seed): running it again writes the same files.

  captures/rtu-shape-three-phase-floats.txt   FC04 blocks of 82 and 60 registers, 64 polls
  captures/rtu-shape-single-phase-floats.txt  FC03 blocks at 0x2000 (16) and 0x4000 (12), 2 polls

Then `mbtap generate captures/X.pcapng --frames captures/X.txt --baud 9600 --parity none`
(see captures/README.md). The answer key of each is in tests/decode/captures.rs.
"""

import random
import struct
import sys


def crc16(data: bytes) -> bytes:
    crc = 0xFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return struct.pack("<H", crc)


def frame(body: bytes) -> str:
    return (body + crc16(body)).hex(" ")


def words_of(value) -> tuple:
    """A float high word first, or a pair of raw words as given."""
    if isinstance(value, tuple):
        return value
    hi, lo = struct.unpack(">HH", struct.pack(">f", value))
    return (hi, lo)


def poll(unit, fc, first, regs):
    req = struct.pack(">BBHH", unit, fc, first, len(regs))
    resp = struct.pack(">BBB", unit, fc, 2 * len(regs)) + b"".join(struct.pack(">H", w) for w in regs)
    return [frame(req), frame(resp)]


def three_phase(rng):
    """Unit 1, input registers 0–81 and 200–259, every value a float high word first."""
    v = [230.4, 231.2, 229.8]
    i3 = 5.0
    p = 0x1000
    energy = 1234.5
    f = 50.0
    out = []
    for k in range(64):
        v = [x + rng.uniform(-0.8, 0.8) for x in v]
        i3 = max(4.5, min(5.5, i3 + rng.uniform(-0.1, 0.1)))
        p = 0x1000 + (k * 0xC0) % 0x3000  # 0x4516 0x1000…0x4000: 2401.0…2404.0 W
        energy += rng.uniform(0.001, 0.01)
        f = 50.0 + rng.uniform(-0.05, 0.05)
        step = (0x4130, 0x4138, 0x4140)[k % 3]  # 11.0, 11.5, 12.0 over an always-zero low word
        a = {
            0: v[0], 2: v[1], 4: v[2],  # voltages 0x4366 xxxx
            6: (0x4151, 0x70A4),  # 13.09 A, never changes
            8: (0x4125, 0x1EB8),  # 10.32 A, never changes
            10: i3,
            12: (0x4516, p), 14: (0x4516, 0x2000), 16: (0x4516, (p + 0x800) % 0x3000 + 0x1000),
            18: 3 * 230.0 * 13.09, 20: 2 * 230.0 * 10.32,
            30: (0x3F33, 0x3333), 32: (0x3F33, 0x3333),  # power factors 0.7, 0.7
            34: (step, 0),
            36: v[0] * 13.09 / 1000.0, 38: v[1] * 10.32 / 1000.0,
            42: (v[0] + v[1] + v[2]) / 3.0,
            46: 13.09 + 10.32 + i3,
            52: 7.2, 56: 3.1,
            60: 8.4, 62: 6.1,
            70: f,
            72: energy, 74: energy / 4.0, 76: 12.5, 78: 0.25,
        }
        block_a = []
        for r in range(0, 82, 2):
            block_a += words_of(a.get(r, (0, 0)))
        b = {
            200: v[0] * 1.732, 202: v[1] * 1.732, 204: v[2] * 1.732, 206: 400.1,
            224: 1.9, 226: 2.2, 228: 2.7, 230: 3.3, 232: 3.6, 234: 4.1,
            240: energy * 0.9, 242: energy * 0.1, 244: 13.09, 246: 10.32,
            250: 41.0, 252: 0.7,
        }
        block_b = []
        for r in range(200, 260, 2):
            block_b += words_of(b.get(r, (0, 0)))
        out += poll(1, 0x04, 0, block_a)
        out += poll(1, 0x04, 200, block_b)
    return out


def single_phase():
    """Unit 1, holding registers 0x2000–0x200F and 0x4000–0x400B, floats high word first, two
    polls; the frequency `0x4248 0x3333` (50.05 Hz) at 8206/8207."""
    out = []
    for k in range(2):
        a = [230.1 + k * 0.3, 4.71 + k * 0.02, 1083.0 + k * 5, 0.0, 1.2, 0.98, 0.0, (0x4248, 0x3333)]
        b = [1521.7 + k * 0.01, 0.0, 2.3, 0.0, 1519.4 + k * 0.01, 0.0]
        out += poll(1, 0x03, 0x2000, sum((list(words_of(x)) for x in a), []))
        out += poll(1, 0x03, 0x4000, sum((list(words_of(x)) for x in b), []))
    return out


HEADER = """# Shapes of the float meter recordings of issue 40 ({what}), made by
# captures/make_float_meters.py — not a recording: no public recording of this shape could be
# found to license. Every value is an IEEE-754 float, high word first; the answer key of
# `mbtap learn` is in tests/decode/captures.rs.
"""


def main(dir_):
    rng = random.Random(40)
    for name, what, frames in [
        ("rtu-shape-three-phase-floats", "a three-phase meter, FC04 blocks of 82 and 60 registers, 64 polls", three_phase(rng)),
        ("rtu-shape-single-phase-floats", "a single-phase meter, FC03 at 0x2000 and 0x4000, two polls", single_phase()),
    ]:
        with open(f"{dir_}/{name}.txt", "w") as f:
            f.write(HEADER.format(what=what))
            f.write("\n".join(frames) + "\n")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "captures")
