"""A pymodbus RTU master polling the simulated devices as fast as they answer, for SECONDS;
prints how many requests it sent and how many were answered. Used by benches/pty_no_loss.sh."""
import sys, time, json
from pymodbus import FramerType
from pymodbus.client import ModbusSerialClient
port, seconds = sys.argv[1], float(sys.argv[2])
c = ModbusSerialClient(port, framer=FramerType.RTU, baudrate=115200, parity="N", timeout=1, retries=0)
assert c.connect()
polls = [("ir", 1, 430, 4), ("ir", 1, 400, 10), ("hr", 1, 100, 10), ("hr", 17, 50, 8), ("ir", 5, 0, 4), ("ir", 5, 44, 22)]
ok = err = 0
end = time.time() + seconds
i = 0
while time.time() < end:
    kind, unit, addr, n = polls[i % len(polls)]; i += 1
    f = c.read_input_registers if kind == "ir" else c.read_holding_registers
    r = f(addr, count=n, device_id=unit)
    if r.isError(): err += 1
    else: ok += 1
print(json.dumps({"requests": i, "ok": ok, "errors": err}))
