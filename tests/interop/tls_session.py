"""One Modbus/TCP Security session kept open while the test drives it: for the bridge's tests
of what happens to a live session (a CRL reloaded under it) and of requests a role must refuse.
Reads lines "UNIT HEXPDU" from stdin and sends each as one MBAP frame on the same TLS session;
prints one JSON line per request: {"answer": "hex PDU"} or {"closed": "why"}; then "ready" on
connecting. Usage: tls_session.py PORT CA CERT KEY"""
import json
import socket
import ssl
import struct
import sys

port, ca, cert, key = int(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4]
ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
ctx.minimum_version = ssl.TLSVersion.TLSv1_2
ctx.load_verify_locations(ca)
ctx.load_cert_chain(cert, key)


def recv_exact(s, n):
    data = b""
    while len(data) < n:
        chunk = s.recv(n - len(data))
        if not chunk:
            raise ConnectionError("closed by the bridge")
        data += chunk
    return data


def say(obj):
    print(json.dumps(obj), flush=True)


s = ctx.wrap_socket(socket.create_connection(("127.0.0.1", port), timeout=10), server_hostname="127.0.0.1")
say({"ready": True})
tid = 0
for line in sys.stdin:
    unit, hexpdu = line.split()
    pdu = bytes.fromhex(hexpdu)
    tid += 1
    try:
        s.sendall(struct.pack(">HHHB", tid, 0, len(pdu) + 1, int(unit)) + pdu)
        head = recv_exact(s, 7)
        body = recv_exact(s, struct.unpack(">H", head[4:6])[0] - 1)
        say({"answer": body.hex()})
    except (ssl.SSLError, ConnectionError, OSError) as e:
        say({"closed": str(e)})
