#!/usr/bin/env python3
"""Scores `mbtap learn` on the inverter shapes of tests/fixtures/learn (made from SunSpec's,
SMA's and Growatt's public maps, each block read once or twice): of the registers the map types
as i16, u32, i32 or text, how many the draft types so (text to its full length), and how many
registers the map calls an integer are drafted as a float (must be none).

  python3 benches/learn_inverters.py [MBTAP]   # default MBTAP: target/release/mbtap
"""

import json
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
SHAPES = os.path.join(HERE, "..", "tests", "fixtures", "learn")


def learned(mbtap, name, tmp):
    pcap = os.path.join(tmp, f"{name}.pcapng")
    subprocess.run([mbtap, "generate", pcap, "--frames", os.path.join(SHAPES, f"{name}.txt"), "--baud", "9600",
                    "--parity", "none", "--force"], check=True, capture_output=True)
    out = subprocess.run([mbtap, "learn", pcap, "--format", "json"], check=True, capture_output=True).stdout
    return json.loads(out)["units"][0]["registers"]


def matches(kind, reg):
    t = reg["type"]
    if kind == "i16":
        return t == "i16"
    if kind == "u32":
        return t.startswith("u32") and t.endswith("high word first")
    if kind == "i32":
        return t == "i32 high word first"
    if kind == "text":
        return t == "string"
    return False


def score(mbtap, name, tmp):
    key = json.load(open(os.path.join(SHAPES, f"{name}.json")))
    regs = {(r["table"], r["address"]): r for r in learned(mbtap, name, tmp)}
    right, wide, total, floats = 0, 0, 0, 0
    missed = []
    for k in key:
        reg = regs.get((k["table"], k["address"]))
        covered = [r for r in regs.values() if r["table"] == k["table"]
                   and r["address"] <= k["address"] < r["address"] + r["width"]]
        if any(r["type"].startswith("f32") for r in covered) and k["type"] != "text":
            floats += 1
        if k["type"] not in ("i16", "u32", "i32", "text"):
            continue
        total += 1
        ok = reg is not None and matches(k["type"], reg) and reg["width"] == k["width"]
        right += ok
        # A 32-bit integer of its width and word order, whatever its sign (a positive S32 is
        # bit for bit a U32: its sign cannot be heard).
        wide += ok or (reg is not None and k["type"] in ("u32", "i32") and reg["width"] == 2
                       and reg["type"].endswith("high word first") and not reg["type"].startswith("f32"))
        if not ok:
            missed.append(f"{k['address']} {k['type']}/{k['width']} → {reg['type'] + '/' + str(reg['width']) if reg else 'nothing'}")
    return right, wide, total, floats, missed


def main():
    mbtap = next((a for a in sys.argv[1:] if not a.startswith("--")), "target/release/mbtap")
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("inverter-sunspec", "inverter-sunspec-103", "inverter-sma", "inverter-growatt"):
            right, wide, total, floats, missed = score(mbtap, name, tmp)
            print(f"{name}: {right}/{total} typed as the map says ({100 * right / total:.0f} %), "
                  f"{wide}/{total} with 32-bit integers of either sign ({100 * wide / total:.0f} %), "
                  f"{floats} integer registers drafted as floats")
            for m in missed:
                print(f"    missed: {m}")


if __name__ == "__main__":
    main()
