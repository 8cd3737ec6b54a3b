"""A pymodbus Modbus TCP server for the reverse-bridge interop test: unit 1 (and only unit 1)
with holding registers 0-99 holding 10 * address. Usage: pymodbus_tcp_server.py PORT"""
import sys

from pymodbus_context import server_context
from pymodbus.server import StartTcpServer

port = int(sys.argv[1])
context = server_context(0, [10 * a for a in range(100)])
StartTcpServer(context=context, address=("127.0.0.1", port))
