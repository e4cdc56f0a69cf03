#!/usr/bin/env python3
"""Import graph of src/: the arrows between top-level modules and between sibling
files of each module, their circles, and arrows that run up the layers
(README, "Module map"). Exit 1 on a circle or an upward arrow.

Usage: python3 scripts/import_graph.py [--edges]
"""
import os, re, sys
from collections import defaultdict

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "src")
# Layers, lowest first; a module may import from its own layer or any lower one.
LAYERS = [
    ["config", "run", "plot", "checkpoint"],  # base: shared loader, run dirs, plots, files
    ["sim"],
    ["terrain", "robot"],
    ["env"],
    ["data", "rl"],
    ["world_model"],
    ["unified", "baselines"],
    ["eval", "collect", "play", "deploy", "bench", "sweep", "benchmark"],
    ["cli", "main"],
]
LEVEL = {m: i for i, layer in enumerate(LAYERS) for m in layer}


def files():
    for d, _, fs in os.walk(ROOT):
        for f in fs:
            if f.endswith(".rs") and f != "lib.rs":
                yield os.path.relpath(os.path.join(d, f), ROOT)


def code(path):
    text = open(os.path.join(ROOT, path)).read()
    # drop comments (doc links name modules without importing them)
    return re.sub(r"//[^\n]*", "", text)


def mod_path(rel):
    parts = rel[:-3].split(os.sep)
    if parts[-1] == "mod":
        parts = parts[:-1]
    return parts  # e.g. ['env', 'rewards']


def main():
    top = defaultdict(set)
    sib = defaultdict(set)
    for rel in files():
        me = mod_path(rel)
        src = code(rel)
        if me[0] in ("main", "cli"):
            deps = set(re.findall(r"\bdreampolicy::(\w+)", src))
        else:
            deps = set(re.findall(r"\bcrate::(\w+)", src))
        for d in deps:
            if d != me[0]:
                top[me[0]].add(d)
        # sibling files: super::x from a file (not mod.rs) inside a module dir
        is_mod = rel.endswith("mod.rs")
        parent = me[:-1] if not is_mod else me[:-1]
        if len(me) >= 2 and not is_mod:
            for d in set(re.findall(r"\bsuper::(\w+)", src)):
                sib[tuple(me)].add(tuple(parent + [d]))
            for d in set(re.findall(r"\bcrate::" + r"::".join(parent) + r"::(\w+)", src)):
                sib[tuple(me)].add(tuple(parent + [d]))
    bad = 0
    names = {tuple(mod_path(r)) for r in files()}
    for a, bs in sorted(sib.items()):
        for b in sorted(bs):
            if b in names and a in sib.get(b, set()) and a < b:
                print(f"circle: {'/'.join(a)} <-> {'/'.join(b)}")
                bad += 1
    for a, bs in sorted(top.items()):
        for b in sorted(bs):
            if a in top.get(b, set()) and a < b:
                print(f"circle: {a} <-> {b}")
                bad += 1
            if a in LEVEL and b in LEVEL and LEVEL[b] > LEVEL[a]:
                print(f"upward: {a} -> {b}")
                bad += 1
            if "--edges" in sys.argv:
                print(f"{a} -> {b}")
    for m in top:
        if m not in LEVEL:
            print(f"unplaced module: {m}")
            bad += 1
    print(f"{bad} problems" if bad else "no circles, no upward arrows")
    sys.exit(1 if bad else 0)


main()
