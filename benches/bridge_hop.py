#!/usr/bin/env python3
"""One client's N reads back to back through `mbtap bridge`, as a whole process to time and pair.

usage: bridge_hop.py MBTAP N tcp|serial
  tcp     the bridge in front of a Modbus TCP device (../shared/trials/bridge/tcp_device.py, or
          $BRIDGE_TOOLS/tcp_device.py): `--serial tcp://DEVICE`, holding registers read
  serial  the bridge in front of `mbtap simulate` on a pseudo-terminal at 115200 baud answering at
          once (the simulator is $SIM, default MBTAP: give both sides of a pair the same one)
WEB=1 adds `--web` and a reader of its event stream (an open page).
Every answer is checked. Time the whole command (e.g. `/usr/bin/time -v`, alternating two
binaries run after run); BENCHMARKS.md keeps the figures."""
import os
import socket
import struct
import subprocess
import sys
import tempfile
import time

mbtap, n, kind = sys.argv[1], int(sys.argv[2]), sys.argv[3]
here = os.path.dirname(os.path.abspath(__file__))
tools = os.environ.get('BRIDGE_TOOLS', os.path.join(here, '..', '..', 'shared', 'trials', 'bridge'))


def free_port():
    s = socket.socket()
    s.bind(('127.0.0.1', 0))
    p = s.getsockname()[1]
    s.close()
    return p


def wait(ready):
    for _ in range(500):
        if ready():
            return
        time.sleep(0.02)
    sys.exit('the device never came up')


def listening(port):
    try:
        socket.create_connection(('127.0.0.1', port), timeout=1).close()
        return True
    except OSError:
        return False


bridge_port = free_port()
if kind == 'tcp':
    device_port = free_port()
    device = subprocess.Popen([sys.executable, os.path.join(tools, 'tcp_device.py'), str(device_port)],
                              stdout=subprocess.DEVNULL)
    wait(lambda: listening(device_port))
    serial = [f'tcp://127.0.0.1:{device_port}']
    function, first = 3, 0      # holding a = 1000 + a
else:
    link = os.path.join(tempfile.mkdtemp(prefix='bridge-hop-'), 'bus')
    device = subprocess.Popen([os.environ.get('SIM', mbtap), 'simulate', '--link', link, '--turnaround-ms', '0',
                               '--baud', '115200'], stderr=subprocess.DEVNULL)
    wait(lambda: os.path.exists(link))
    serial = [link, '--baud', '115200']
    function, first = 4, 430    # the MK4's phase voltages
# WEB=1: the bridge serves its live view (--web) and a reader follows its event stream the whole
# run, as an open page would — to pair against the same binary without it.
web = []
if os.environ.get('WEB'):
    web_port = free_port()
    web = ['--web', f'127.0.0.1:{web_port}']
bridge = subprocess.Popen([mbtap, 'bridge', '--serial', *serial, '--listen', f'127.0.0.1:{bridge_port}', *web],
                          stderr=subprocess.DEVNULL)
wait(lambda: listening(bridge_port))
if web:
    import threading
    page = socket.create_connection(('127.0.0.1', web_port))
    page.sendall(b'GET /events HTTP/1.1\r\nHost: x\r\n\r\n')
    threading.Thread(target=lambda: [None for _ in iter(lambda: page.recv(65536), b'')], daemon=True).start()
c = socket.create_connection(('127.0.0.1', bridge_port))
c.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
for i in range(n):
    address = first + i % 2
    c.sendall(struct.pack('>HHHBBHH', i & 0xFFFF, 0, 6, 1, function, address, 2))
    answer = b''
    while len(answer) < 13:
        got = c.recv(13 - len(answer))
        if not got:
            sys.exit('the bridge closed the connection')
        answer += got
    assert answer[:2] == struct.pack('>H', i & 0xFFFF) and answer[7] == function, answer
    if kind == 'tcp':
        assert struct.unpack('>HH', answer[9:13]) == (1000 + address, 1001 + address), answer
c.close()
for p in (bridge, device):
    p.terminate()
    p.wait()
