"""Reads a SunSpec device with pysunspec2 (the SunSpec Alliance's reference implementation) and
prints its points as JSON: {"MODEL[INSTANCE].POINT": computed value or null} for the common and
inverter models, and the model IDs of the chain. Usage: pysunspec_read.py tcp PORT | rtu SERIAL-PORT"""
import json
import sys

import sunspec2.modbus.client as client

if sys.argv[1] == "tcp":
    d = client.SunSpecModbusClientDeviceTCP(slave_id=1, ipaddr="127.0.0.1", ipport=int(sys.argv[2]))
else:
    d = client.SunSpecModbusClientDeviceRTU(slave_id=1, name=sys.argv[2], baudrate=19200, parity="N")
d.scan()
out = {}
for name in ["common", "inverter_three_phase"]:
    for i, m in enumerate(d.models.get(name, [])):
        for p in ["Mn", "Md", "Vr", "SN", "DA", "A", "AphA", "AphB", "PhVphA", "W", "Hz", "WH", "TmpCab", "St", "VA"]:
            if p in m.points:
                out[f"{name}[{i + 1}].{p}"] = m.points[p].cvalue
d.close()
print(json.dumps(out))
