"""pymodbus as a Modbus TCP client reading one range: prints JSON, {"registers": [...]} or
{"exception": CODE}. Usage: pymodbus_tcp_read.py HOST PORT UNIT holding|input|coils ADDRESS COUNT"""
import inspect
import json
import sys

from pymodbus.client import ModbusTcpClient

host, port, unit, table, address, count = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], int(sys.argv[5]), int(sys.argv[6])
client = ModbusTcpClient(host, port=port, timeout=3, retries=0)
if not client.connect():
    sys.exit(f"cannot connect to {host}:{port}")
read = {"holding": client.read_holding_registers, "input": client.read_input_registers, "coils": client.read_coils}[table]
# The unit keyword changed name across pymodbus 3.x releases (slave -> device_id).
key = "device_id" if "device_id" in inspect.signature(read).parameters else "slave"
r = read(address, count=count, **{key: unit})
if r.isError():
    print(json.dumps({"exception": getattr(r, "exception_code", None)}))
elif table == "coils":
    print(json.dumps({"bits": [bool(b) for b in r.bits[:count]]}))
else:
    print(json.dumps({"registers": list(r.registers)}))
client.close()
