#!/usr/bin/env python3
"""Check a bundle's ONNX policy with Python onnxruntime, a runtime we did not write.

Usage: third_party/pyenv/bin/python scripts/check_onnx_python.py BUNDLE [BUNDLE...]

BUNDLE is a directory written by `dreampolicy export --format onnx`. For each,
onnxruntime (CPU) loads `policy.onnx` and runs it on the reference inputs of
`policy_reference.npz` (rows of a rollout of the policy and random rows, raw
inputs as the graph takes them), batched and one row at a time; its actions
must equal the TorchScript file's, stored beside them, to 1e-5. Prints one
JSON line per bundle; exits 1 on a mismatch, 2 on a missing or malformed file.
"""
import json
import sys
from pathlib import Path

import numpy as np
import onnxruntime as ort

sys.path.insert(0, str(Path(__file__).resolve().parent))
from check_tfevents_python import fields  # noqa: E402

TOL = 1e-5


def fail(code, msg):
    print(f"check_onnx_python: {msg}", file=sys.stderr)
    sys.exit(code)


def check(bundle: Path) -> dict:
    onnx_file, ref_file = bundle / "policy.onnx", bundle / "policy_reference.npz"
    for f in (onnx_file, ref_file):
        if not f.is_file():
            fail(2, f"{f}: missing (write the bundle with `dreampolicy export --format onnx`)")
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    sess = ort.InferenceSession(str(onnx_file), opts, providers=["CPUExecutionProvider"])
    names = [i.name for i in sess.get_inputs()]
    if names != ["obs", "history", "scan"] or [o.name for o in sess.get_outputs()] != ["action"]:
        fail(2, f"{onnx_file}: inputs {names}, outputs {[o.name for o in sess.get_outputs()]}")
    ref = np.load(ref_file)
    meta = sess.get_modelmeta().custom_metadata_map
    out = {
        "bundle": str(bundle),
        "onnxruntime": ort.__version__,
        "opset": _opsets(onnx_file),
        "history_len": int(meta.get("history_len", -1)),
    }
    worst = 0.0
    for tag in ("rollout", "random"):
        feeds = {n: ref[f"{tag}_{n}"].astype(np.float32) for n in names}
        want = ref[f"{tag}_action"]
        got = sess.run(["action"], feeds)[0]
        if got.shape != want.shape:
            fail(1, f"{bundle}: {tag} actions shaped {got.shape}, expected {want.shape}")
        diff = float(np.abs(got - want).max())
        # the batch dimension is free: one row at a time gives the same
        rows = np.concatenate(
            [sess.run(["action"], {n: v[i : i + 1] for n, v in feeds.items()})[0] for i in range(len(want))]
        )
        diff = max(diff, float(np.abs(rows - want).max()))
        out[f"{tag}_rows"] = int(len(want))
        out[f"{tag}_max_abs_diff"] = diff
        out[f"{tag}_action_abs_max"] = float(np.abs(want).max())
        worst = max(worst, diff)
    out["ok"] = worst <= TOL
    return out


def _opsets(onnx_file: Path):
    """The model's opset versions, read from the protobuf without the onnx package
    (the protobuf field reader of check_tfevents_python.py): ModelProto field 8
    (opset_import) holds OperatorSetIdProto {1: domain, 2: version}."""
    found = []
    for field, _, value in fields(onnx_file.read_bytes()):
        if field == 8:
            found += [v for f, w, v in fields(value) if f == 2 and w == 0]
    return found


def main():
    if len(sys.argv) < 2:
        fail(2, __doc__.strip().splitlines()[2])
    ok = True
    for arg in sys.argv[1:]:
        r = check(Path(arg))
        print(json.dumps(r))
        ok &= r["ok"]
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
