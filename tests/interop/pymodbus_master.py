"""A pymodbus serial master for the interop tests: reads and writes the simulated devices of
`mbtap simulate` and prints what it got as one JSON object. Usage: pymodbus_master.py PORT rtu|ascii"""
import inspect
import json
import sys

from pymodbus import FramerType
from pymodbus.client import ModbusSerialClient

port, mode = sys.argv[1], sys.argv[2]
# Parity none: a pseudo-terminal ignores parity, and pyserial on recent glibc reports the
# ignored PARENB as EINVAL when it re-applies its settings.
client = ModbusSerialClient(port, framer=FramerType.RTU if mode == "rtu" else FramerType.ASCII,
                            baudrate=19200, parity="N", stopbits=1, bytesize=8, timeout=2, retries=1)
if not client.connect():
    sys.exit(f"cannot open {port}")

# The unit keyword changed name across pymodbus 3.x releases (slave -> device_id).
UNIT = "device_id" if "device_id" in inspect.signature(client.read_holding_registers).parameters else "slave"


def unit(n):
    return {UNIT: n}


def registers(r):
    return None if r.isError() else list(r.registers)


def exception(r):
    return getattr(r, "exception_code", None) if r.isError() else None


out = {
    "mk4_voltages": registers(client.read_input_registers(430, count=4, **unit(1))),
    "mk4_write_108": not client.write_register(108, 2500, **unit(1)).isError(),
    "mk4_read_108": registers(client.read_holding_registers(108, count=1, **unit(1))),
    "mk4_write_108_clamped": not client.write_register(108, 30000, **unit(1)).isError(),
    "mk4_read_108_after_clamp": registers(client.read_holding_registers(108, count=1, **unit(1))),
    "mk4_coils": None,
    "mk4_outside_map_exception": exception(client.read_holding_registers(1000, count=1, **unit(1))),
    "mkzp_currents": registers(client.read_holding_registers(50, count=3, **unit(17))),
    "mkzp_input_registers_exception": exception(client.read_input_registers(50, count=1, **unit(17))),
    "display_totals": registers(client.read_input_registers(0, count=4, **unit(5))),
}
coils = client.read_coils(0, count=3, **unit(1))
out["mk4_coils"] = None if coils.isError() else [bool(b) for b in coils.bits[:3]]
client.close()
print(json.dumps(out))
