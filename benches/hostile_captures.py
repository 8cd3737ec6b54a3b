#!/usr/bin/env python3
"""Writes the three hostile pcapng files behind BENCHMARKS.md's "memory against hostile
captures" table: each is a valid file built to make a reader's memory follow it.

    python3 benches/hostile_captures.py DIR

bigpacket.pcapng  one Enhanced Packet Block of 16 MiB - 32 bytes (the largest block we accept)
idbflood.pcapng   100 000 Interface Description Blocks, each with a 1000-byte if_description
twoif.pcapng      two interfaces, 3000 packets of 60 000 bytes alternating between them
All use link type 147 (USER0) and little-endian blocks (pcapng draft, sections 4.1-4.3).
"""
import os
import struct
import sys

LINKTYPE_USER0 = 147
T0_US = 1_700_000_000_000_000  # microseconds (if_tsresol default, 10^-6)


def block(kind, body):
    # Block Type, Block Total Length, body padded to 32 bits, Block Total Length again.
    body += b"\0" * (-len(body) % 4)
    total = 12 + len(body)
    return struct.pack("<II", kind, total) + body + struct.pack("<I", total)


def shb():
    # Byte-Order Magic, major 1, minor 0, section length unknown (-1).
    return block(0x0A0D0D0A, struct.pack("<IHHq", 0x1A2B3C4D, 1, 0, -1))


def idb(description=None):
    body = struct.pack("<HHI", LINKTYPE_USER0, 0, 0)
    if description is not None:
        # if_description (code 3), then opt_endofopt.
        body += struct.pack("<HH", 3, len(description)) + description
        body += b"\0" * (-len(body) % 4) + struct.pack("<HH", 0, 0)
    return block(1, body)


def epb(interface, t_us, data):
    head = struct.pack("<IIIII", interface, t_us >> 32, t_us & 0xFFFFFFFF, len(data), len(data))
    return block(6, head + data)


def main(out):
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "bigpacket.pcapng"), "wb") as f:
        f.write(shb() + idb() + epb(0, T0_US, bytes(i % 251 for i in range(16 * 1024 * 1024 - 64))))
    with open(os.path.join(out, "idbflood.pcapng"), "wb") as f:
        f.write(shb() + idb())
        one = idb(b"x" * 1000)
        for _ in range(100_000):
            f.write(one)
    with open(os.path.join(out, "twoif.pcapng"), "wb") as f:
        f.write(shb() + idb() + idb())
        payload = bytes(i % 251 for i in range(60_000))
        for i in range(3000):
            f.write(epb(i % 2, T0_US + 100 * i, payload))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "target/hostile")
