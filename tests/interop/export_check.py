"""Checks what `mbtap profiles export` writes with the tools that read it:

  export_check.py home-assistant FILE   Home Assistant's own `modbus` CONFIG_SCHEMA (the
                                        homeassistant package), as its configuration check does
  export_check.py telegraf FILE         parses as TOML; [[inputs.modbus]] with the plugin's keys,
                                        register entries with its data types and byte orders

(ESPHome is checked with its own `esphome config FILE`.) Prints one JSON object with what was
checked; exit status 1 when the tool refuses the file or nothing was checked."""
import json
import sys

kind, path = sys.argv[1], sys.argv[2]
result = {"kind": kind, "file": path}

if kind == "home-assistant":
    import yaml

    import types

    # As in ha_discovery_check.py: the bootstrap first, for an import cycle among components.
    import homeassistant.bootstrap  # noqa: F401

    # The integration's runtime half (the hub, which imports the pymodbus release Home Assistant
    # pins, older than the one the other interop tests use) is not needed to check a
    # configuration: its module is stood in for, the schema and validators are Home Assistant's.
    runtime = types.ModuleType("homeassistant.components.modbus.modbus")
    runtime.ModbusHub = runtime.async_modbus_setup = None
    sys.modules[runtime.__name__] = runtime
    from homeassistant.components import modbus

    with open(path, encoding="utf-8") as f:
        doc = yaml.safe_load(f)
    try:
        checked = modbus.CONFIG_SCHEMA(doc)
    except Exception as e:  # voluptuous.Invalid
        print(json.dumps({**result, "refused": str(e)}))
        sys.exit(1)
    hub = checked["modbus"][0]
    result["sensors"] = len(hub.get("sensors", []))
    result["binary_sensors"] = len(hub.get("binary_sensors", []))
    ok = result["sensors"] + result["binary_sensors"] > 0
elif kind == "telegraf":
    import tomllib

    with open(path, "rb") as f:
        doc = tomllib.load(f)
    plugin = doc["inputs"]["modbus"][0]
    problems = []
    for key in ["name", "slave_id", "timeout", "controller", "configuration_type"]:
        if key not in plugin:
            problems.append(f"missing {key}")
    allowed = {"name", "slave_id", "timeout", "controller", "configuration_type", "coils", "discrete_inputs",
               "holding_registers", "input_registers"}
    problems += [f"unknown key {k}" for k in plugin if k not in allowed]
    types = {"INT16", "UINT16", "INT32", "UINT32", "FLOAT32-IEEE"}
    orders = {"AB", "BA", "ABCD", "CDAB", "BADC", "DCBA"}
    count = 0
    for table in ["holding_registers", "input_registers"]:
        for r in plugin.get(table, []):
            count += 1
            if r.get("data_type") not in types:
                problems.append(f"{r.get('name')}: data_type {r.get('data_type')}")
            if r.get("byte_order") not in orders:
                problems.append(f"{r.get('name')}: byte_order {r.get('byte_order')}")
            width = 2 if r["data_type"] in {"INT32", "UINT32", "FLOAT32-IEEE"} else 1
            if len(r["address"]) != width or len(r["byte_order"]) != 2 * width:
                problems.append(f"{r.get('name')}: {len(r['address'])} addresses for {r['data_type']} {r['byte_order']}")
            if not isinstance(r.get("scale"), float):
                problems.append(f"{r.get('name')}: scale must be a float")
    for table in ["coils", "discrete_inputs"]:
        for r in plugin.get(table, []):
            count += 1
            if set(r) != {"name", "address"} or len(r["address"]) != 1:
                problems.append(f"{r}: a bit takes a name and one address")
    names = [r["name"] for t in ["coils", "discrete_inputs", "holding_registers", "input_registers"]
             for r in plugin.get(t, [])]
    if len(set(names)) != len(names):
        problems.append("names repeat")
    result["registers_and_bits"] = count
    if problems:
        print(json.dumps({**result, "refused": problems[:10]}))
        sys.exit(1)
    ok = count > 0
else:
    sys.exit(f"unknown kind {kind}")

print(json.dumps(result))
sys.exit(0 if ok else 1)
