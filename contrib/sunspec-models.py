"""Condenses the SunSpec Alliance's model definitions (the JSON files pysunspec2 ships, Apache-2.0)
into crates/mbtap-device/src/sunspec/models.json: per model its ID, group name, top-level points
(name, type, size in registers, scale-factor point, units) and its first repeating group.
Run: python3 contrib/sunspec-models.py  (needs pysunspec2)."""
import glob
import importlib.metadata
import json
import os

import sunspec2

src = os.path.join(os.path.dirname(sunspec2.__file__), "models", "json")


def points(group):
    return [[p["name"], p["type"], p.get("size", 1), p.get("sf"), p.get("units")] for p in group.get("points", [])]


models = []
for path in sorted(glob.glob(os.path.join(src, "model_*.json")), key=lambda p: int(p.split("_")[-1][:-5])):
    with open(path, encoding="utf-8") as f:
        m = json.load(f)
    g = m["group"]
    model = {"id": m["id"], "name": g["name"], "points": points(g)}
    for sub in g.get("groups", []):
        count = sub.get("count", 1)
        if count != 1:
            model["repeat"] = {"name": sub["name"], "count": count, "points": points(sub)}
            break
    models.append(model)

out = os.path.join(os.path.dirname(__file__), "..", "crates", "mbtap-device", "src", "sunspec", "models.json")
with open(out, "w", encoding="utf-8") as f:
    version = importlib.metadata.version("pysunspec2")
    source = f"pysunspec2 {version} models/json (SunSpec Alliance, Apache-2.0)"
    json.dump({"source": source, "models": models}, f, separators=(",", ":"))
print(out, len(models), "models", os.path.getsize(out), "bytes")
