"""pymodbus's TLS client reading holding registers 104-105 of unit 1 through the bridge's
Modbus/TCP Security listener with a client certificate (its TLS framer carries the MBAP
header and the PDU, as MODBUS/TCP Security says). Prints JSON {"registers": [...]} or {"error": "..."}.
Usage: pymodbus_tls_read.py PORT CA CERT KEY"""
import inspect
import json
import ssl
import sys

from pymodbus.client import ModbusTlsClient

port, ca, cert, key = int(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4]
ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
ctx.load_verify_locations(ca)
ctx.load_cert_chain(cert, key)
# pymodbus wraps its socket without a server name: the chain is still verified against the CA
# (CERT_REQUIRED), only the name check is left to the raw-ssl client of tls_client.py.
ctx.check_hostname = False
client = ModbusTlsClient("127.0.0.1", sslctx=ctx, port=port, timeout=3, retries=0)
if not client.connect():
    print(json.dumps({"error": "cannot connect"}))
    sys.exit(0)
unit = "device_id" if "device_id" in inspect.signature(client.read_holding_registers).parameters else "slave"
r = client.read_holding_registers(104, count=2, **{unit: 1})
print(json.dumps({"error": str(r)} if r.isError() else {"registers": list(r.registers)}))
client.close()
