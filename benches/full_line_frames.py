#!/usr/bin/env python3
"""Frames of a full line for `mbtap generate --frames`: 247 units, each read over its whole
holding and input tables in blocks of 125 registers (FC 03/04, MAP v1.1b3 §6.3), request then
answer, values `address XOR unit`. 259 350 transactions: the recording `simulate --from` must keep
every unit of (BENCHMARKS.md, "simulate --from: a store per unit").

Usage: python3 benches/full_line_frames.py > /tmp/full.txt
       mbtap generate /tmp/full.pcapng --frames /tmp/full.txt --baud 115200
"""
import struct
import sys


def crc16(data: bytes) -> bytes:
    crc = 0xFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return struct.pack("<H", crc)


def main() -> None:
    out = sys.stdout
    for unit in range(1, 248):
        for fc in (3, 4):
            for start in range(0, 65536, 125):
                n = min(125, 65536 - start)
                req = struct.pack(">BBHH", unit, fc, start, n)
                resp = struct.pack(">BBB", unit, fc, 2 * n) + b"".join(
                    struct.pack(">H", (a ^ unit) & 0xFFFF) for a in range(start, start + n)
                )
                out.write((req + crc16(req)).hex(" ") + "\n")
                out.write((resp + crc16(resp)).hex(" ") + "\n")


if __name__ == "__main__":
    main()
