#!/usr/bin/env python3
"""A least-squares linear predictor of the next H states from the last K, on a
collected dataset: the floor a world model should beat.

Fits on 9 of every 10 episodes of the first two shards, scores the tenth, in the
dataset's normalized units (stats.json), per horizon step and per state block,
next to holding the last state and the dataset mean.

    python3 -m venv /tmp/np && /tmp/np/bin/pip install numpy mcap
    /tmp/np/bin/python scripts/linear_probe.py runs/dataset [K] [H] [SHARDS]

SHARDS: comma-separated shard numbers to read instead of 0,1 (e.g. 4,6,8,10
for one shard of each terrain kind of the turning dataset).
"""
import json
import sys

import numpy as np
from mcap.reader import make_reader

S = 98
BLOCKS = {"ang_vel": slice(0, 3), "gravity": slice(3, 6), "dof_pos": slice(6, 35),
          "dof_vel": slice(35, 64), "command": slice(64, 67), "last_action": slice(67, 96),
          "phase": slice(96, 98)}


def main():
    ds = sys.argv[1]
    k = int(sys.argv[2]) if len(sys.argv) > 2 else 4
    h = int(sys.argv[3]) if len(sys.argv) > 3 else 8
    shards = [int(v) for v in sys.argv[4].split(",")] if len(sys.argv) > 4 else [0, 1]
    st = json.load(open(f"{ds}/stats.json"))
    mean = np.array(st["state"]["mean"])
    std = np.array(st["state"]["std"])
    std[std < 1e-8] = 1.0
    eps = {}
    for shard in (f"shard-{i:05d}.mcap" for i in shards):
        try:
            f = open(f"{ds}/{shard}", "rb")
        except FileNotFoundError:
            continue
        with f:
            for _, _, m in make_reader(f).iter_messages(topics=["/frames"]):
                d = m.data
                ep = (shard, int.from_bytes(d[0:8], "little"))
                eps.setdefault(ep, []).append(np.frombuffer(d[80:80 + 4 * S], dtype="<f4"))
    xs, ys, ids = [], [], []
    for i, frames in enumerate(eps.values()):
        z = (np.array(frames) - mean) / std
        for t in range(k, len(z) - h + 1, 3):
            xs.append(z[t - k:t].reshape(-1))
            ys.append(z[t:t + h])
            ids.append(i)
    x, y, ids = np.array(xs), np.array(ys), np.array(ids)
    val = ids % 10 == 0
    xa = np.hstack([x, np.ones((len(x), 1))])
    w = np.linalg.lstsq(xa[~val], y[~val].reshape((~val).sum(), -1), rcond=None)[0]
    p = (xa[val] @ w).reshape(-1, h, S)
    hold = np.repeat(x[val][:, None, -S:], h, axis=1)
    rmse = lambda a: np.sqrt(((a - y[val]) ** 2).mean(axis=(0, 2)))
    print(f"{(~val).sum()} train and {val.sum()} validation windows, K {k}, H {h}")
    print("RMSE per horizon step (normalized)")
    print("  linear :", np.round(rmse(p), 3))
    print("  hold   :", np.round(rmse(hold), 3))
    print(f"  mean state: {np.sqrt((y[val] ** 2).mean()):.3f}")
    print(f"MSE over all steps: linear {((p - y[val]) ** 2).mean():.3f}, "
          f"hold {((hold - y[val]) ** 2).mean():.3f}, mean {(y[val] ** 2).mean():.3f}")
    for name, sl in BLOCKS.items():
        print(f"  {name:12s} MSE linear {((p - y[val])[:, :, sl] ** 2).mean():.3f}"
              f"  hold {((hold - y[val])[:, :, sl] ** 2).mean():.3f}")


if __name__ == "__main__":
    main()
