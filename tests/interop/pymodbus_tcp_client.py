"""pymodbus as a Modbus TCP client through `mbtap bridge` to the simulated devices: reads,
writes, a device exception and the gateway's own 0x0B, checked against the profiles' documents.
Usage: pymodbus_tcp_client.py HOST PORT [udp]: Modbus TCP, or Modbus UDP (the bridge's
--listen-udp). Prints ALL OK or exits non-zero saying what failed."""
import inspect
import sys

from pymodbus.client import ModbusTcpClient, ModbusUdpClient

host, port = sys.argv[1], int(sys.argv[2])
Client = ModbusUdpClient if sys.argv[3:] == ["udp"] else ModbusTcpClient
client = Client(host, port=port, timeout=3, retries=0)
if not client.connect():
    sys.exit(f"cannot connect to {host}:{port}")

# The unit keyword changed name across pymodbus 3.x releases (slave -> device_id).
UNIT = "device_id" if "device_id" in inspect.signature(client.read_holding_registers).parameters else "slave"


def unit(n):
    return {UNIT: n}


def check(what, ok, got):
    if not ok:
        sys.exit(f"{what}: got {got}")


r = client.read_input_registers(430, count=4, **unit(1))
check("MK4 voltages", not r.isError() and all(2200 <= v <= 2400 for v in r.registers), r)
r = client.write_register(105, 1234, **unit(1))
check("MK4 write level 2 set point", not r.isError(), r)
r = client.read_holding_registers(105, count=1, **unit(1))
check("MK4 read it back", not r.isError() and r.registers == [1234], r)
r = client.read_holding_registers(50, count=3, **unit(17))
check("MKZP phase currents (% of nominal)", not r.isError() and all(70 <= v <= 100 for v in r.registers), r)
r = client.read_input_registers(1000, count=1, **unit(1))
check("MK4 address outside its map: exception 02", r.isError() and getattr(r, "exception_code", None) == 2, r)
r = client.read_holding_registers(0, count=1, **unit(9))
check("no device at 9: gateway exception 0x0B", r.isError() and getattr(r, "exception_code", None) == 0x0B, r)
client.close()
print("ALL OK")
