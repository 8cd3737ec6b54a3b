"""A Modbus RTU device on a pseudo-terminal that answers late (regression of hostile
round 3 `watch_swap.sh`): holding register N holds 1000 + N; every FC03 request is answered after
DELAY_MS. usage: late_slave.py LINK DELAY_MS   (LINK: the symlink made to the pty; runs until
killed)."""
import os
import sys
import time


def crc16(data):
    crc = 0xFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return bytes([crc & 0xFF, crc >> 8])


link, delay = sys.argv[1], int(sys.argv[2]) / 1000
master, slave = os.openpty()
import tty  # noqa: E402

tty.setraw(slave)
if os.path.lexists(link):
    os.remove(link)
os.symlink(os.ttyname(slave), link)
buf = b""
while True:
    buf += os.read(master, 256)
    # A read request is 8 bytes: unit, 03, address, quantity, CRC.
    while len(buf) >= 8:
        req, buf = buf[:8], buf[8:]
        if req[1] != 3 or crc16(req[:6]) != req[6:8]:
            buf = b""
            break
        addr, qty = int.from_bytes(req[2:4], "big"), int.from_bytes(req[4:6], "big")
        body = bytes([req[0], 3, 2 * qty]) + b"".join((1000 + addr + i).to_bytes(2, "big") for i in range(qty))
        time.sleep(delay)
        os.write(master, body + crc16(body))
