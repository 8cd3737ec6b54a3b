"""A pymodbus Modbus ASCII server on a serial port, for the ASCII bridge's interop test: unit 1
with holding registers 0-99 holding 10 * address. Usage: pymodbus_ascii_server.py PORT"""
import sys

from pymodbus_context import server_context
from pymodbus.server import StartSerialServer

try:
    from pymodbus import FramerType
    ASCII = FramerType.ASCII
except ImportError:  # older 3.x
    from pymodbus.framer import ModbusAsciiFramer as ASCII

port = sys.argv[1]
context = server_context(0, [10 * a for a in range(100)])
StartSerialServer(context=context, framer=ASCII, port=port, baudrate=19200, bytesize=8, parity="N", stopbits=1)
