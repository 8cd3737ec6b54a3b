"""A pymodbus Modbus ASCII server on a serial port, for the ASCII bridge's interop test: unit 1
with holding registers 0-99 holding 10 * address. Usage: pymodbus_ascii_server.py PORT"""
import sys

import pymodbus.datastore as ds
from pymodbus.server import StartSerialServer

try:
    from pymodbus import FramerType
    ASCII = FramerType.ASCII
except ImportError:  # older 3.x
    from pymodbus.framer import ModbusAsciiFramer as ASCII

port = sys.argv[1]
# The per-device context was renamed across pymodbus 3.x (ModbusSlaveContext -> ModbusDeviceContext).
Device = getattr(ds, "ModbusDeviceContext", None) or getattr(ds, "ModbusSlaveContext")
block = ds.ModbusSequentialDataBlock(1, [10 * a for a in range(100)])
try:
    device = Device(hr=block)
except TypeError:
    device = Device(di=None, co=None, hr=block, ir=None)
try:
    context = ds.ModbusServerContext(devices={1: device}, single=False)
except TypeError:
    context = ds.ModbusServerContext(slaves={1: device}, single=False)
# 8N1 on the pty: a pseudo-terminal ignores parity and character size, and pyserial's
# tcsetattr for 7E1 fails on one (EINVAL); ASCII frames are plain characters either way.
StartSerialServer(context=context, framer=ASCII, port=port, baudrate=19200, bytesize=8, parity="N", stopbits=1)
