"""A Sparkplug B host for mbtap's tests: subscribes to the whole spBv1.0 namespace on a broker
and prints each message as one JSON line, its payload decoded with the Sparkplug
specification's own sparkplug_b.proto (the compiled copy pysparkplug ships); or sends an NCMD
asking a node for a rebirth.

    sparkplug_host.py listen PORT
    sparkplug_host.py rebirth PORT GROUP NODE
"""

import json
import sys
import time

import paho.mqtt.client as mqtt
from google.protobuf.json_format import MessageToDict
from pysparkplug._protobuf import sparkplug_b_pb2 as pb


def on_message(_client, _userdata, msg):
    line = {"topic": msg.topic, "t": time.time()}
    if msg.topic.startswith("spBv1.0/STATE/"):
        line["state"] = msg.payload.decode("utf-8", "replace")
    else:
        p = pb.Payload()
        try:
            p.ParseFromString(msg.payload)
            line["payload"] = MessageToDict(p, preserving_proto_field_name=True)
        except Exception as e:  # noqa: BLE001 - a payload the spec's schema refuses is reported
            line["error"] = str(e)
    print(json.dumps(line), flush=True)


def client(client_id, persistent):
    """A paho client (1.x or 2.x); `persistent`: the broker keeps its subscription and queues for
    it while it is away or the broker restarts (a host must not miss stored-and-forwarded data)."""
    kwargs = {"client_id": client_id, "clean_session": not persistent}
    if hasattr(mqtt, "CallbackAPIVersion"):
        return mqtt.Client(mqtt.CallbackAPIVersion.VERSION1, **kwargs)
    return mqtt.Client(**kwargs)


def listen(port):
    c = client(f"sparkplug-host-{port}", True)
    c.on_message = on_message
    c.on_connect = lambda cl, *_: (cl.subscribe("spBv1.0/#", qos=1), print(json.dumps({"ready": True}), flush=True))
    c.connect("127.0.0.1", port)
    c.loop_forever()


def rebirth(port, group, node):
    p = pb.Payload()
    p.timestamp = int(time.time() * 1000)
    m = p.metrics.add()
    m.name = "Node Control/Rebirth"
    m.datatype = 11  # Boolean
    m.boolean_value = True
    c = client(f"sparkplug-cmd-{port}", False)
    c.connect("127.0.0.1", port)
    c.loop_start()
    c.publish(f"spBv1.0/{group}/NCMD/{node}", p.SerializeToString(), qos=0).wait_for_publish()
    c.loop_stop()
    c.disconnect()


if __name__ == "__main__":
    if sys.argv[1] == "listen":
        listen(int(sys.argv[2]))
    else:
        rebirth(int(sys.argv[2]), sys.argv[3], sys.argv[4])
