#!/usr/bin/env python3
"""Read our MCAP files with the reference MCAP reader of another language (the
`mcap` Python package, with `zstandard` for zstd chunks):

* dataset shards (`dreampolicy.dataset` metadata): every record parses, every frame
  message has `frame_bytes` bytes, the message count matches the summary, and the
  first frame's header decodes;
* play files (`dreampolicy play`, `dreampolicy.play` metadata): every channel has its
  Foxglove or dreampolicy schema (JSON Schema text naming itself) and JSON messages,
  every message decodes as JSON, `/tf` holds one transform per robot body in `world`
  with unit quaternions and the `/robot` entities' frames, timestamps increase per
  topic, and the per-topic counts agree (`/tf`, `/state`, `/command`: one per frame;
  `/reward`: one per frame after the first; `/robot`, `/terrain`: one).

    python3 scripts/check_mcap_python.py [--require] DIR_OR_FILE...

A directory is checked shard by shard (`*.mcap` in it). The reader comes from the
current interpreter or else from the venv that scripts/setup.sh makes
(third_party/pyenv). Without it the script exits 0 with a note, or 1 with --require
(CI).
"""
import json
import math
import pathlib
import struct
import sys

try:
    from mcap.reader import make_reader
except ImportError:
    from _venv import reexec_in_venv

    reexec_in_venv(__file__)
    if "--require" in sys.argv[1:]:
        raise SystemExit(
            "the mcap Python package is not installed: run scripts/setup.sh "
            "(it makes the venv third_party/pyenv)"
        )
    print("skipped: the mcap Python package is not installed (scripts/setup.sh installs it)")
    sys.exit(0)

PLAY_SCHEMAS = {
    "/tf": "foxglove.FrameTransforms",
    "/robot": "foxglove.SceneUpdate",
    "/terrain": "foxglove.SceneUpdate",
    "/command": "dreampolicy.Command",
    "/state": "dreampolicy.State",
    "/reward": "dreampolicy.Reward",
}


def fail(path, why):
    raise SystemExit(f"{path}: {why}")


def check_shard(path, reader, meta):
    info = json.loads(meta.metadata["json"])
    size = info["frame_bytes"]
    summary = reader.get_summary()
    count, first = 0, None
    for _schema, channel, message in reader.iter_messages():
        if channel.topic != "/frames" or channel.message_encoding != info["format"]:
            fail(path, f"unexpected channel {channel.topic}")
        if len(message.data) != size:
            fail(path, f"message of {len(message.data)} bytes, frame_bytes {size}")
        if first is None:
            first = message.data
        count += 1
    expected = summary.statistics.message_count
    if count != expected:
        fail(path, f"{count} messages, the summary says {expected}")
    episode, env, step, level, kind, flags = struct.unpack_from("<QIIIBB", first, 0)
    pos = struct.unpack_from("<3d", first, 24)
    print(
        f"ok {path}: {count} frames of {size} bytes, dims {info['dims']}, "
        f"first frame episode {episode} env {env} step {step} "
        f"{info['terrain_kinds'][kind]} level {level} pos {pos}"
    )


def check_play(path, reader, meta):
    summary = reader.get_summary()
    topics = {c.topic: c for c in summary.channels.values()}
    if sorted(topics) != sorted(PLAY_SCHEMAS):
        fail(path, f"channels {sorted(topics)}, expected {sorted(PLAY_SCHEMAS)}")
    for topic, name in PLAY_SCHEMAS.items():
        channel = topics[topic]
        schema = summary.schemas[channel.schema_id]
        if schema.name != name or schema.encoding != "jsonschema":
            fail(path, f"{topic}: schema {schema.name} ({schema.encoding}), expected {name} (jsonschema)")
        if channel.message_encoding != "json":
            fail(path, f"{topic}: message encoding {channel.message_encoding}")
        if json.loads(schema.data).get("title") != name:
            fail(path, f"{topic}: the JSON Schema's title is not {name}")

    counts = {t: 0 for t in PLAY_SCHEMAS}
    last_time = {}
    bodies, body_frames = None, None
    steps = []
    for _schema, channel, message in reader.iter_messages(log_time_order=False):
        topic = channel.topic
        msg = json.loads(message.data)
        if topic in last_time and message.log_time <= last_time[topic]:
            fail(path, f"{topic}: log time {message.log_time} after {last_time[topic]}")
        last_time[topic] = message.log_time
        counts[topic] += 1
        if topic == "/robot":
            body_frames = {e["frame_id"] for e in msg["entities"]}
            if not all(e["frame_locked"] for e in msg["entities"]):
                fail(path, "/robot: an entity is not frame-locked")
        elif topic == "/terrain":
            if not msg["entities"] or msg["entities"][0]["frame_id"] != "world":
                fail(path, "/terrain: no entity in the world frame")
        elif topic == "/tf":
            tfs = msg["transforms"]
            if bodies is None:
                bodies = len(tfs)
            if len(tfs) != bodies or bodies == 0:
                fail(path, f"/tf: {len(tfs)} transforms, the first message had {bodies}")
            for t in tfs:
                q = t["rotation"]
                n = math.sqrt(q["x"] ** 2 + q["y"] ** 2 + q["z"] ** 2 + q["w"] ** 2)
                if abs(n - 1.0) > 1e-4 or t["parent_frame_id"] != "world":
                    fail(path, f"/tf: {t['child_frame_id']}: |q| = {n}, parent {t['parent_frame_id']}")
                stamp = t["timestamp"]["sec"] * 10**9 + t["timestamp"]["nsec"]
                if stamp != message.log_time:
                    fail(path, f"/tf: stamp {stamp} != log time {message.log_time}")
            if body_frames is not None and {t["child_frame_id"] for t in tfs} != body_frames:
                fail(path, "/tf: child frames differ from the /robot entities' frames")
        elif topic == "/state":
            steps.append(msg["step"])
            if not all(isinstance(msg[k], (int, float)) for k in ("vx", "distance", "base_height")):
                fail(path, "/state: missing numbers")
        elif topic == "/reward":
            if not isinstance(msg["terms"], dict) or not isinstance(msg["total"], (int, float)):
                fail(path, "/reward: no terms or total")
    frames = counts["/tf"]
    expected = {"/tf": frames, "/state": frames, "/command": frames,
                "/reward": max(frames - 1, 0), "/robot": 1, "/terrain": 1}
    if counts != expected or frames == 0:
        fail(path, f"message counts {counts}, expected {expected}")
    if steps != list(range(frames)):
        fail(path, "/state: steps are not 0, 1, 2, ...")
    if sum(counts.values()) != summary.statistics.message_count:
        fail(path, f"{sum(counts.values())} messages, the summary says {summary.statistics.message_count}")
    info = meta.metadata
    print(
        f"ok {path}: play of {info['checkpoint']} on {info['terrain']} (level {info['level']}): "
        f"{frames} frames of {bodies} bodies, {sum(counts.values())} JSON messages on "
        f"{len(counts)} topics"
    )


def check(path):
    with open(path, "rb") as f:
        reader = make_reader(f)
        meta = {m.name: m for m in reader.iter_metadata()}
        if "dreampolicy.dataset" in meta:
            check_shard(path, reader, meta["dreampolicy.dataset"])
        elif "dreampolicy.play" in meta:
            check_play(path, reader, meta["dreampolicy.play"])
        else:
            fail(path, f"neither a dataset shard nor a play file (metadata {sorted(meta)})")


paths = [a for a in sys.argv[1:] if a != "--require"]
for arg in paths or ["."]:
    p = pathlib.Path(arg)
    for file in sorted(p.glob("*.mcap")) if p.is_dir() else [p]:
        check(file)
