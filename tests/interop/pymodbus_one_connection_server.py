"""A pymodbus Modbus TCP server that serves one connection at a time, as many meters and
inverters do: a connection made while another is open is closed at once. Units 1 and 2, holding
registers 0-99 holding 10 * address. Prints "accepted" or "refused" for each connection
(flushed), for the test to count. Usage: pymodbus_one_connection_server.py PORT"""
import asyncio
import sys

from pymodbus_context import server_context
from pymodbus.server import ModbusTcpServer


class Refuse(asyncio.Protocol):
    def connection_made(self, transport):
        print("refused", flush=True)
        transport.close()


class OneAtATime(ModbusTcpServer):
    def handle_new_connection(self):
        if self.active_connections:
            return Refuse()
        print("accepted", flush=True)
        return super().handle_new_connection()


async def main():
    context = server_context(0, [10 * a for a in range(100)], units=(1, 2))
    server = OneAtATime(context=context, address=("127.0.0.1", int(sys.argv[1])))
    await server.serve_forever()


asyncio.run(main())
