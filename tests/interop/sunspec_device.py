"""A simulated SunSpec device for the SunSpec interop test: a pymodbus Modbus TCP
server, unit 1, whose holding registers hold "SunS" at 40000 and the chain: common (1), a
three-phase inverter (103), a second 103 (a repeated model), a model nobody defines (64999),
then the end marker. Points not set hold their type's "not implemented" value. The model
layouts come from pysunspec2's definitions, as a vendor's would follow the specification.
Usage: sunspec_device.py tcp PORT | rtu SERIAL-PORT (19200 8N1)"""
import json
import os
import sys

import sunspec2
from pymodbus_context import server_context
from pymodbus.server import StartTcpServer

MODELS = os.path.join(os.path.dirname(sunspec2.__file__), "models", "json")
NOT_IMPLEMENTED = {"int16": [0x8000], "sunssf": [0x8000], "int32": [0x8000, 0], "float32": [0x7FC0, 0],
                   "acc16": [0], "acc32": [0, 0], "acc64": [0, 0, 0, 0], "int64": [0x8000, 0, 0, 0]}


def words(value, kind, size):
    if kind == "string":
        b = value.encode().ljust(2 * size, b"\0")
        return [int.from_bytes(b[i:i + 2], "big") for i in range(0, 2 * size, 2)]
    if kind == "float32":
        import struct
        b = struct.pack(">f", value)
        return [int.from_bytes(b[0:2], "big"), int.from_bytes(b[2:4], "big")]
    v = value & ((1 << (16 * size)) - 1)
    return [(v >> (16 * (size - 1 - i))) & 0xFFFF for i in range(size)]


def model(mid, values):
    with open(os.path.join(MODELS, f"model_{mid}.json"), encoding="utf-8") as f:
        points = json.load(f)["group"]["points"]
    regs = []
    for p in points:
        size, kind = p.get("size", 1), p["type"]
        if p["name"] == "ID":
            regs += [mid]
        elif p["name"] == "L":
            regs += [sum(q.get("size", 1) for q in points) - 2]
        elif p["name"] in values:
            regs += words(values[p["name"]], kind, size)
        elif kind == "string" or kind == "pad":
            regs += [0] * size
        else:
            regs += (NOT_IMPLEMENTED.get(kind, []) + [0xFFFF] * size)[:size]
    return regs


common = model(1, {"Mn": "mbtap", "Md": "SIM-3 inverter", "Vr": "1.2.3", "SN": "SN-0042", "DA": 1})
inverter = {"A": 123, "A_SF": -1, "AphA": 41, "PhVphA": 2301, "PhVphB": 2299, "V_SF": -1, "W": 4500, "W_SF": 0,
            "Hz": 5001, "Hz_SF": -2, "WH": 1234567, "WH_SF": 0, "TmpCab": 412, "Tmp_SF": -1, "St": 4}
second = dict(inverter, W=2000, A=87)
image = [0x5375, 0x6E53] + common + model(103, inverter) + model(103, second) + [64999, 4, 1, 2, 3, 4] + [0xFFFF, 0]
context = server_context(40000, image)
if sys.argv[1] == "tcp":
    StartTcpServer(context=context, address=("127.0.0.1", int(sys.argv[2])))
else:
    from pymodbus import FramerType
    from pymodbus.server import StartSerialServer

    StartSerialServer(context=context, framer=FramerType.RTU, port=sys.argv[2], baudrate=19200, bytesize=8,
                      parity="N", stopbits=1)
