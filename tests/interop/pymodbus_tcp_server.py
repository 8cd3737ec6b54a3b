"""A pymodbus Modbus TCP server for the reverse-bridge interop test: unit 1 (and only unit 1)
with holding registers 0-99 holding 10 * address. Usage: pymodbus_tcp_server.py PORT"""
import sys

import pymodbus.datastore as ds
from pymodbus.server import StartTcpServer

port = int(sys.argv[1])
# The per-device context was renamed across pymodbus 3.x (ModbusSlaveContext -> ModbusDeviceContext).
Device = getattr(ds, "ModbusDeviceContext", None) or getattr(ds, "ModbusSlaveContext")
# Block address 1 holds protocol address 0 (the device context adds 1, as Modbus numbering does).
block = ds.ModbusSequentialDataBlock(1, [10 * a for a in range(100)])
try:
    device = Device(hr=block)
except TypeError:
    device = Device(di=None, co=None, hr=block, ir=None)
try:
    context = ds.ModbusServerContext(devices={1: device}, single=False)
except TypeError:
    context = ds.ModbusServerContext(slaves={1: device}, single=False)
StartTcpServer(context=context, address=("127.0.0.1", port))
