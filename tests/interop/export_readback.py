"""Reads an mbtap export back as its tool's YAML 1.1 or TOML reader would:

  export_readback.py yaml|toml FILE EXPECTED_JSON

PyYAML's SafeLoader is the YAML 1.1 reader Home Assistant and ESPHome are built on: NEL, LS and
PS end a line there (a comment included) and plain `yes`, `1:20`, `1_000` are typed. EXPECTED_JSON
is {"top": [keys], "names": [register names]}: the file must have exactly those top-level keys
and every name must come back as the same string. Prints one JSON line; exit 1 on any difference."""
import json
import sys

kind, path, expected = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
raw = open(path, "rb").read().decode("utf-8")
if kind == "yaml":
    import yaml

    doc = yaml.load(raw, Loader=yaml.SafeLoader)
else:
    import tomllib

    doc = tomllib.loads(raw)

names = []


def walk(v):
    if isinstance(v, dict):
        if "name" in v and ("address" in v or "platform" in v):
            names.append(v["name"])
        for x in v.values():
            walk(x)
    elif isinstance(v, list):
        for x in v:
            walk(x)


walk(doc)
problems = []
if sorted(doc) != sorted(expected["top"]):
    problems.append(f"top-level keys {sorted(doc)} != {sorted(expected['top'])}")
for n in expected["names"]:
    if n not in names:
        problems.append(f"name {n!r} not read back (got {names!r})"[:400])
for n in names:
    if not isinstance(n, str):
        problems.append(f"name {n!r} read as {type(n).__name__}")
print(json.dumps({"file": path, "names": len(names), "problems": problems}))
sys.exit(1 if problems else 0)
