"""A Modbus/TCP Security client for the bridge's TLS tests: Python's ssl module with a client
certificate (or none), one read of holding registers 104-105 and one write of 105 on unit 1,
raw MBAP frames. Prints JSON: {"read": [...] | {"exception": n}, "write": "ok" | {"exception": n}}
or {"handshake": "failed: ..."}. Usage: tls_client.py PORT CA [CERT KEY]"""
import json
import socket
import ssl
import struct
import sys

port, ca = int(sys.argv[1]), sys.argv[2]
ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
ctx.minimum_version = ssl.TLSVersion.TLSv1_2
ctx.load_verify_locations(ca)
if len(sys.argv) > 4:
    ctx.load_cert_chain(sys.argv[3], sys.argv[4])


def call(s, tid, pdu):
    s.sendall(struct.pack(">HHHB", tid, 0, len(pdu) + 1, 1) + pdu)
    head = b""
    while len(head) < 7:
        chunk = s.recv(7 - len(head))
        if not chunk:
            raise ConnectionError("closed")
        head += chunk
    length = struct.unpack(">H", head[4:6])[0] - 1
    body = b""
    while len(body) < length:
        chunk = s.recv(length - len(body))
        if not chunk:
            raise ConnectionError("closed")
        body += chunk
    return body


out = {}
try:
    raw = socket.create_connection(("127.0.0.1", port), timeout=5)
    s = ctx.wrap_socket(raw, server_hostname="127.0.0.1")
    # TLS 1.3 reports a refused client certificate only at the first read.
    r = call(s, 1, bytes([0x03, 0x00, 0x68, 0x00, 0x02]))
    out["read"] = {"exception": r[1]} if r[0] & 0x80 else list(struct.unpack(">HH", r[2:6]))
    w = call(s, 2, bytes([0x06, 0x00, 0x69, 0x00, 0x07]))
    out["write"] = {"exception": w[1]} if w[0] & 0x80 else "ok"
except (ssl.SSLError, ConnectionError, OSError) as e:
    out = {"handshake": f"failed: {e}"}
print(json.dumps(out))
