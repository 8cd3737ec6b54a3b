"""A Sparkplug B host for mbtap's tests: subscribes to the whole spBv1.0 namespace on a broker
and prints each message as one JSON line, its payload decoded with the Sparkplug
specification's own sparkplug_b.proto (the compiled copy pysparkplug ships); or sends an NCMD
asking a node for a rebirth.

    sparkplug_host.py listen PORT
    sparkplug_host.py rebirth PORT GROUP NODE
    sparkplug_host.py dcmd PORT GROUP NODE DEVICE METRIC VALUE   (a Double)
    sparkplug_host.py state PORT HOST_ID online|offline            (retained, Sparkplug 3.0 JSON)
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


def command(port, topic, name, datatype, field, value):
    p = pb.Payload()
    p.timestamp = int(time.time() * 1000)
    m = p.metrics.add()
    m.name = name
    m.datatype = datatype
    setattr(m, field, value)
    c = client(f"sparkplug-cmd-{port}", False)
    c.connect("127.0.0.1", port)
    c.loop_start()
    c.publish(topic, p.SerializeToString(), qos=0).wait_for_publish()
    c.loop_stop()
    c.disconnect()


if __name__ == "__main__":
    port = int(sys.argv[2])
    if sys.argv[1] == "listen":
        listen(port)
    elif sys.argv[1] == "state":
        body = json.dumps({"online": sys.argv[4] == "online", "timestamp": int(time.time() * 1000)})
        c = client(f"sparkplug-state-{port}", False)
        c.connect("127.0.0.1", port)
        c.loop_start()
        c.publish(f"spBv1.0/STATE/{sys.argv[3]}", body, qos=1, retain=True).wait_for_publish()
        c.loop_stop()
        c.disconnect()
    elif sys.argv[1] == "rebirth":
        topic = f"spBv1.0/{sys.argv[3]}/NCMD/{sys.argv[4]}"
        command(port, topic, "Node Control/Rebirth", 11, "boolean_value", True)  # Boolean
    else:
        topic = f"spBv1.0/{sys.argv[3]}/DCMD/{sys.argv[4]}/{sys.argv[5]}"
        command(port, topic, sys.argv[6], 10, "double_value", float(sys.argv[7]))  # Double
