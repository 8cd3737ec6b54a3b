"""Validates mbtap's Home Assistant MQTT discovery messages with Home Assistant's own schemas
(the `homeassistant` package's MQTT sensor, binary_sensor, number, select and switch DISCOVERY_SCHEMA), as Home
Assistant does when the message arrives. Reads "TOPIC PAYLOAD" lines (mosquitto_sub -v) on
stdin; prints one JSON object: {"checked": N, "by_component": {...}, "refused": [[topic, why]]}.
Exit status 1 when any was refused or none was checked."""
import json
import sys

# Importing the bootstrap first settles an import cycle among the http, websocket_api and
# persistent_notification components that a direct import of the MQTT platforms runs into.
import homeassistant.bootstrap  # noqa: F401
from homeassistant.components.mqtt import binary_sensor, number, select, sensor, switch
# The pattern Home Assistant matches a discovery topic against (after its prefix): node and object
# ids of [a-zA-Z0-9_-] only; a topic it does not match is logged as illegal and ignored.
from homeassistant.components.mqtt.discovery import TOPIC_MATCHER

schemas = {
    "sensor": sensor.DISCOVERY_SCHEMA,
    "binary_sensor": binary_sensor.DISCOVERY_SCHEMA,
    "number": number.DISCOVERY_SCHEMA,
    "select": select.DISCOVERY_SCHEMA,
    "switch": switch.DISCOVERY_SCHEMA,
}
checked, refused, by_component = 0, [], {}
for line in sys.stdin:
    topic, _, payload = line.rstrip("\n").partition(" ")
    parts = topic.split("/")
    # An empty config (mosquitto_sub -v prints it as "(null)") removes the entity: Home
    # Assistant's documented way to take one back (`--mqtt-forget`, a demo's end), not a config.
    if len(parts) < 4 or parts[-1] != "config" or payload in ("", "(null)"):
        continue
    component = parts[1]
    if not TOPIC_MATCHER.match("/".join(parts[1:])):
        refused.append([topic, "Home Assistant's discovery topic pattern does not match it (ids must be [a-zA-Z0-9_-])"])
        continue
    schema = schemas.get(component)
    if schema is None:
        refused.append([topic, f"component {component} is not one mbtap announces"])
        continue
    checked += 1
    by_component[component] = by_component.get(component, 0) + 1
    try:
        schema(json.loads(payload))
    except Exception as e:  # voluptuous.Invalid and JSON errors alike
        refused.append([topic, str(e)])
print(json.dumps({"checked": checked, "by_component": by_component, "refused": refused}))
sys.exit(1 if refused or checked == 0 else 0)
