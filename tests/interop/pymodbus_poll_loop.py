"""A pymodbus RTU master polling one range again and again (the "inverter" on its own port):
prints one JSON object counting answers equal to EXPECTED (comma-separated registers), other
answers, and errors. Usage: pymodbus_poll_loop.py PORT UNIT input|holding ADDRESS COUNT SECONDS EXPECTED"""
import inspect
import json
import sys
import time

from pymodbus import FramerType
from pymodbus.client import ModbusSerialClient

port, unit, table, address, count, seconds = sys.argv[1], int(sys.argv[2]), sys.argv[3], int(sys.argv[4]), int(sys.argv[5]), float(sys.argv[6])
expected = [int(v) for v in sys.argv[7].split(",")]
# Parity none: a pseudo-terminal ignores parity, and pyserial on recent glibc reports the
# ignored PARENB as EINVAL when it re-applies its settings.
client = ModbusSerialClient(port, framer=FramerType.RTU, baudrate=19200, parity="N", stopbits=1, bytesize=8,
                            timeout=2, retries=0)
if not client.connect():
    sys.exit(f"cannot open {port}")
read = client.read_input_registers if table == "input" else client.read_holding_registers
key = "device_id" if "device_id" in inspect.signature(read).parameters else "slave"
right = wrong = errors = 0
first_wrong = None
end = time.monotonic() + seconds
while time.monotonic() < end:
    r = read(address, count=count, **{key: unit})
    if r.isError():
        errors += 1
    elif list(r.registers) == expected:
        right += 1
    else:
        wrong += 1
        first_wrong = first_wrong or list(r.registers)
    time.sleep(0.05)
print(json.dumps({"right": right, "wrong": wrong, "errors": errors, "first_wrong": first_wrong}))
