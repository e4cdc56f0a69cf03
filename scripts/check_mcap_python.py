#!/usr/bin/env python3
"""Read dataset shards with the reference MCAP reader of another language (the
`mcap` Python package, plus `zstandard` for zstd chunks): every record parses, the
`dreampolicy.dataset` metadata is there, every frame message has `frame_bytes`
bytes, the message count matches the summary, and the first frame's header decodes.

    python3 scripts/check_mcap_python.py DIR_OR_FILE...

Optional like check_stock_mujoco.py: exits 0 with a note when `mcap` is not importable.
"""
import json
import pathlib
import struct
import sys

try:
    from mcap.reader import make_reader
except ImportError:
    print("skipped: the mcap Python package is not installed (pip install mcap zstandard)")
    sys.exit(0)


def check(path):
    with open(path, "rb") as f:
        reader = make_reader(f)
        meta = [m for m in reader.iter_metadata() if m.name == "dreampolicy.dataset"]
        if len(meta) != 1:
            raise SystemExit(f"{path}: {len(meta)} dreampolicy.dataset metadata records")
        info = json.loads(meta[0].metadata["json"])
        size = info["frame_bytes"]
        summary = reader.get_summary()
        count, first = 0, None
        for _schema, channel, message in reader.iter_messages():
            if channel.topic != "/frames" or channel.message_encoding != info["format"]:
                raise SystemExit(f"{path}: unexpected channel {channel.topic}")
            if len(message.data) != size:
                raise SystemExit(f"{path}: message of {len(message.data)} bytes, frame_bytes {size}")
            if first is None:
                first = message.data
            count += 1
        expected = summary.statistics.message_count
        if count != expected:
            raise SystemExit(f"{path}: {count} messages, the summary says {expected}")
        episode, env, step, level, kind, flags = struct.unpack_from("<QIIIBB", first, 0)
        pos = struct.unpack_from("<3d", first, 24)
        print(
            f"ok {path}: {count} frames of {size} bytes, dims {info['dims']}, "
            f"first frame episode {episode} env {env} step {step} "
            f"{info['terrain_kinds'][kind]} level {level} pos {pos}"
        )


for arg in sys.argv[1:] or ["."]:
    p = pathlib.Path(arg)
    for shard in sorted(p.glob("*.mcap")) if p.is_dir() else [p]:
        check(shard)
