#!/usr/bin/env python3
"""How a `dreampolicy play` rollout went, step by step, read from its MCAP file:
where each foot landed against the lane's terrain, flights, and the heading.

    python3 scripts/play_trace.py FILE.mcap [--steps A:B] [--straddle-height 0.03] [--json]

Prints a summary (steps, distance, touchdowns, touchdowns across an edge,
flight steps and the longest flight, the largest heading error; the same over
the last 2 s, which for a fall are the 2 s before it: `play` prints the
ending), and with `--steps A:B` (not with `--json`) one line per control step
from A to B: time, yaw, pitch, roll, contacts (left, right), then for each
foot its ankle position and the terrain under the sole's heel, ankle and toe.

The terrain is the lane's triangle mesh on `/terrain` (a plane lane has none:
height 0), read as the heightfield's triangles (split along (c, r)-(c+1, r+1));
feet are the ankle-roll links on `/tf`, contacts the `/state` flags. A touchdown
lands "across an edge" when the terrain under the sole's four corners (heel
-0.05 m and toe +0.13 m along the foot, +-0.026 m across, `src/robot.rs`)
spans more than `--straddle-height`: the env's `feet_straddle` rule. A
touchdown ends a swing of 2 or more control steps; a flight is a step with
neither foot in contact.

The reader comes from the current interpreter or else from the venv that
scripts/setup.sh makes (third_party/pyenv).
"""
import argparse
import json
import math
import sys

try:
    from mcap.reader import make_reader
except ImportError:
    from _venv import reexec_in_venv

    reexec_in_venv(__file__)
    raise SystemExit("the mcap Python package is not installed: run scripts/setup.sh")

SOLE_X = (-0.05, 0.13)
SOLE_HALF_WIDTH = 0.026
FEET = ("left_ankle_roll_link", "right_ankle_roll_link")
# a touchdown ends a swing of at least this many control steps (a contact flag
# that drops for one step while the foot drags is not a step)
MIN_AIR_STEPS = 2


class Terrain:
    """Heights of the lane's mesh: its vertices lie on a regular grid."""

    def __init__(self, points):
        self.z = {}
        self.d = None
        if not points:
            return
        xs = sorted({round(p["x"], 6) for p in points})
        self.d = min(b - a for a, b in zip(xs, xs[1:])) if len(xs) > 1 else 1.0
        self.x0 = min(p["x"] for p in points)
        self.y0 = min(p["y"] for p in points)
        for p in points:
            c = round((p["x"] - self.x0) / self.d)
            r = round((p["y"] - self.y0) / self.d)
            self.z[(c, r)] = p["z"]

    def height(self, x, y):
        if self.d is None:
            return 0.0
        gx, gy = (x - self.x0) / self.d, (y - self.y0) / self.d
        c, r = math.floor(gx), math.floor(gy)
        u, v = gx - c, gy - r
        h = [self.z.get(k) for k in ((c, r), (c + 1, r), (c, r + 1), (c + 1, r + 1))]
        if None in h:
            return float("nan")
        h00, h10, h01, h11 = h
        if u >= v:
            return h00 + u * (h10 - h00) + v * (h11 - h10)
        return h00 + v * (h01 - h00) + u * (h11 - h01)


def rotate(q, p):
    """Rotate point p by the unit quaternion q (x, y, z, w)."""
    x, y, z, w = q["x"], q["y"], q["z"], q["w"]
    px, py, pz = p
    tx, ty, tz = 2 * (y * pz - z * py), 2 * (z * px - x * pz), 2 * (x * py - y * px)
    return (
        px + w * tx + (y * tz - z * ty),
        py + w * ty + (z * tx - x * tz),
        pz + w * tz + (x * ty - y * tx),
    )


def sole(terrain, t, q, dx, dy):
    ox, oy, _ = rotate(q, (dx, dy, 0.0))
    return terrain.height(t["x"] + ox, t["y"] + oy)


def load(path):
    states, feet, points = [], [], None
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            topic = channel.topic
            if topic == "/state":
                states.append(json.loads(message.data))
            elif topic == "/tf":
                tf = {t["child_frame_id"]: t for t in json.loads(message.data)["transforms"]}
                feet.append([(tf[n]["translation"], tf[n]["rotation"]) for n in FEET])
            elif topic == "/terrain":
                points = []
                for e in json.loads(message.data)["entities"]:
                    for tri in e.get("triangles", []):
                        points.extend(tri["points"])
    if not states or len(states) != len(feet):
        raise SystemExit(f"{path}: not a play file (/state and /tf per frame)")
    return states, feet, Terrain(points)


def summarize(states, feet, terrain, lo, straddle_height):
    touch = straddled = flight = longest = run = 0
    yaw_err = 0.0
    air = [0, 0]  # control steps each foot has been off the ground
    for i in range(lo + 1, len(states)):
        s = states[i]
        contact = (s["left_contact"], s["right_contact"])
        for k in range(2):
            if not contact[k]:
                air[k] += 1
                continue
            landed, air[k] = air[k] >= MIN_AIR_STEPS, 0
            if landed:
                touch += 1
                t, q = feet[i][k]
                hs = [
                    sole(terrain, t, q, x, y)
                    for x in SOLE_X
                    for y in (-SOLE_HALF_WIDTH, SOLE_HALF_WIDTH)
                ]
                if max(hs) - min(hs) > straddle_height:
                    straddled += 1
        if not contact[0] and not contact[1]:
            flight += 1
            run += 1
            longest = max(longest, run)
        else:
            run = 0
        yaw_err = max(yaw_err, abs(s["yaw"]))
    return {
        "steps": len(states) - 1 - lo,
        "touchdowns": touch,
        "touchdowns_across_edge": straddled,
        "flight_steps": flight,
        "longest_flight_steps": longest,
        "max_abs_yaw": round(yaw_err, 3),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("file")
    ap.add_argument("--steps", help="A:B, print control steps A to B (B excluded)")
    ap.add_argument("--straddle-height", type=float, default=0.03)
    ap.add_argument("--json", action="store_true", help="print the summary as JSON only")
    a = ap.parse_args()
    states, feet, terrain = load(a.file)
    last = states[-1]
    out = {"file": a.file, "seconds": round(last["time"], 2), "distance": round(last["distance"], 3)}
    out.update(summarize(states, feet, terrain, 0, a.straddle_height))
    out["last_2s"] = summarize(states, feet, terrain, max(0, len(states) - 101), a.straddle_height)
    if a.steps and not a.json:
        lo, hi = (int(v) if v else None for v in a.steps.split(":"))
        for i in range(len(states))[slice(lo, hi)]:
            s = states[i]
            line = (
                f"{s['time']:6.2f} yaw {s['yaw']:+.2f} pitch {s['pitch']:+.2f} roll {s['roll']:+.2f}"
                f" contact {s['left_contact']}{s['right_contact']}"
            )
            for k, side in enumerate("LR"):
                t, q = feet[i][k]
                hs = " ".join(f"{sole(terrain, t, q, x, 0.0):+.3f}" for x in (SOLE_X[0], 0.0, SOLE_X[1]))
                line += f" | {side} ({t['x']:.2f}, {t['y']:.2f}, {t['z']:.3f}) ground {hs}"
            print(line)
    print(json.dumps(out, indent=None if a.json else 1))


if __name__ == "__main__":
    main()
