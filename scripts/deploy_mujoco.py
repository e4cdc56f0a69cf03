#!/usr/bin/env python3
"""Walk a dreampolicy deployment bundle in stock Python MuJoCo.

Reads only the bundle (`deploy.yaml` and `policy.npz`, both written by
`dreampolicy export --checkpoint F --out DIR`) and a scene file; builds each
observation from what the robot measures (the pelvis quaternion and gyro, the
joint encoders), runs the actor in NumPy, and sends position targets to the
scene's actuators, as unitree_rl_gym's deploy_mujoco.py does. Prints one JSON
object: distance, speed, tracking error, final yaw, fall.

    third_party/pyenv/bin/python scripts/deploy_mujoco.py --bundle DIR \
        [--scene models/g1/scene_flat.xml] [--seconds 20] [--speed 0.75] \
        [--noise-seed 0] [--runtime numpy|onnx]

With `--runtime onnx` the actor is the bundle's `policy.onnx` run by
onnxruntime (a bundle written with `export --format onnx`; GRU encoders too)
instead of the NumPy arrays of `policy.npz`.

The bundle's seal is checked first: `deploy.yaml` ends in
`# dreampolicy-sha256: <hex>` (the SHA-256 of the lines above it) and lists the
SHA-256 of `policy.pt` and `policy.npz` under `files`; a damaged or edited
bundle is refused.

Needs mujoco, numpy and pyyaml (scripts/python.lock, installed by setup.sh into
third_party/pyenv), and onnxruntime for `--runtime onnx`. The NumPy actor runs
MLP-history and history-free policies; a GRU encoder is refused with a message
(use `--runtime onnx` or `dreampolicy deploy-sim`).
"""
import argparse
import hashlib
import json
import math
import os
import sys

import mujoco
import numpy as np
import yaml

FALL_HEIGHT = 0.45
FALL_TILT_DEG = 50.0


SEAL_PREFIX = "# dreampolicy-sha256: "


def check_bundle(bundle_dir, text, b):
    """Refuse a bundle whose deploy.yaml or policy files changed after export."""
    path = os.path.join(bundle_dir, "deploy.yaml")
    body, _, last = text.rstrip("\n").rpartition("\n")
    body = body + "\n" if body else ""
    if not last.startswith(SEAL_PREFIX):
        raise SystemExit(f"{path}: has no integrity seal; write the bundle again with "
                         "`dreampolicy export`")
    if hashlib.sha256(body.encode()).hexdigest() != last[len(SEAL_PREFIX):]:
        raise SystemExit(f"{path}: is corrupt: its SHA-256 does not match its seal line")
    names = [b["policy"]["file"], "policy.npz"]
    if b.get("onnx_policy"):
        names += [b["onnx_policy"]["file"], b["onnx_policy"]["reference"]]
    for name in names:
        digest = (b.get("files") or {}).get(name)
        if digest is None:
            raise SystemExit(f"{path}: holds no SHA-256 for {name}")
        with open(os.path.join(bundle_dir, name), "rb") as f:
            if hashlib.sha256(f.read()).hexdigest() != digest:
                raise SystemExit(f"{os.path.join(bundle_dir, name)}: is corrupt: its SHA-256 "
                                 "does not match the one in deploy.yaml")


def act_fn(name):
    if name == "elu":
        return lambda x: np.where(x > 0, x, np.expm1(np.minimum(x, 0)))
    if name == "relu":
        return lambda x: np.maximum(x, 0)
    if name == "tanh":
        return np.tanh
    raise SystemExit(f"unknown activation {name!r} in deploy.yaml")


class Policy:
    """The actor of `policy.npz`: [hist(history), scan_actor(scan), obs] -> MLP."""

    def __init__(self, bundle_dir, spec):
        self.w = np.load(os.path.join(bundle_dir, spec["file"]))
        self.spec = spec
        self.act = act_fn(spec["activation"])
        if spec["history"] == "gru" or spec.get("scan_encoder", "mlp") == "gru":
            raise SystemExit("the NumPy deployer runs MLP encoders only; "
                             "use `dreampolicy deploy-sim` for a GRU policy")

    def norm(self, x, kind):
        if not self.spec["normalize"]:
            return x
        clip = self.spec["obs_clip" if kind == "obs" else "scan_clip"]
        return np.clip((x - self.w[kind + "_mean"]) / self.w[kind + "_std"], -clip, clip)

    def layers(self, name, n, x, last_activation):
        for i in range(n):
            x = x @ self.w[f"{name}.{i}.weight"].T + self.w[f"{name}.{i}.bias"]
            if i < n - 1 or last_activation:
                x = self.act(x)
        return x

    def __call__(self, obs, history, scan):
        parts = []
        if self.spec["history"] == "mlp" and len(history):
            h = np.concatenate([self.norm(o, "obs") for o in history])
            parts.append(self.layers("hist", self.spec["hist_layers"], h, True))
        if self.spec["scan_layers"]:
            parts.append(self.layers("scan_actor", self.spec["scan_layers"],
                                     self.norm(scan, "scan"), True))
        parts.append(self.norm(obs, "obs"))
        return self.layers("actor", self.spec["actor_layers"], np.concatenate(parts), False)


class OnnxPolicy:
    """The bundle's `policy.onnx` in onnxruntime: (obs, history, scan) -> action mean."""

    def __init__(self, bundle_dir, spec):
        import onnxruntime as ort

        opts = ort.SessionOptions()
        opts.intra_op_num_threads = 1
        self.sess = ort.InferenceSession(os.path.join(bundle_dir, spec["file"]), opts,
                                         providers=["CPUExecutionProvider"])

    def __call__(self, obs, history, scan):
        f = lambda x: np.asarray(x, dtype=np.float32)[None]
        hist = np.asarray(history, dtype=np.float32).reshape(len(history), len(obs))
        feeds = {"obs": f(obs), "history": hist[None], "scan": f(scan)}
        return self.sess.run(["action"], feeds)[0][0].astype(np.float64)


def quat_to_mat(q):
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--bundle", required=True)
    p.add_argument("--scene", help="default: the bundle's scene, from the repository root")
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--speed", type=float, default=0.75)
    p.add_argument("--noise-seed", type=int, help="add the training observation noise")
    p.add_argument("--check-actions", metavar="JSON",
                   help="instead of walking: compare the NumPy actor's actions with the "
                        "cases in this file ([{obs, history, scan, action}], written by the "
                        "tests from the TorchScript policy); exit 1 past 1e-4")
    p.add_argument("--runtime", choices=["numpy", "onnx"], default="numpy",
                   help="the actor: policy.npz in NumPy, or policy.onnx in onnxruntime")
    a = p.parse_args()

    path = os.path.join(a.bundle, "deploy.yaml")
    try:
        with open(path) as f:
            text = f.read()
    except OSError as e:
        raise SystemExit(f"{path}: {e.strerror}")
    try:
        b = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise SystemExit(f"{path}: not YAML ({str(e).splitlines()[0]})")
    if not isinstance(b, dict):
        raise SystemExit(f"{path}: not a deploy.yaml mapping")
    check_bundle(a.bundle, text, b)
    if b.get("format") != "dreampolicy-deploy/1":
        raise SystemExit(f"{path}: format {b.get('format')!r}, this script reads dreampolicy-deploy/1")
    if a.runtime == "onnx":
        if not b.get("onnx_policy"):
            raise SystemExit(f"{path}: has no ONNX policy; write the bundle with "
                             "`dreampolicy export --format onnx`")
        policy = OnnxPolicy(a.bundle, b["onnx_policy"])
    else:
        policy = Policy(a.bundle, b["numpy_policy"])
    if a.check_actions:
        worst = 0.0
        for case in json.load(open(a.check_actions)):
            ours = policy(np.array(case["obs"]), [np.array(h) for h in case["history"]],
                          np.array(case["scan"]))
            worst = max(worst, float(np.max(np.abs(ours - np.array(case["action"])))))
        print(json.dumps({"cases": len(json.load(open(a.check_actions))), "max_abs_diff": worst}))
        return 0 if worst < 1e-4 else 1
    root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
    scene = a.scene or os.path.join(root, b["scene"])
    m = mujoco.MjModel.from_xml_path(scene)
    t = b["timing"]
    m.opt.timestep = t["physics_dt"]
    d = mujoco.MjData(m)

    free = next(j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE)
    fq, fv = m.jnt_qposadr[free], m.jnt_dofadr[free]
    joints = b["joints"]
    qadr = np.array([m.jnt_qposadr[m.joint(j["name"]).id] for j in joints])
    vadr = np.array([m.jnt_dofadr[m.joint(j["name"]).id] for j in joints])
    act = np.array([m.actuator(j["actuator"]).id for j in joints])
    default = np.array([j["default_pos"] for j in joints])
    scale = np.array([j["action_scale"] for j in joints])

    key = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, b["reset"]["keyframe"])
    if key >= 0:
        mujoco.mj_resetDataKeyframe(m, d, key)
    d.qpos[qadr] = default
    d.ctrl[act] = default
    d.qpos[fq + 2] = b["reset"]["pelvis_height"]
    mujoco.mj_forward(m, d)

    o = b["observation"]
    noise = o["noise"]
    rng = np.random.default_rng(a.noise_seed) if a.noise_seed is not None else None
    k = b["policy"]["history_len"]
    clip = b["action"]["clip"]
    c = b["commands"]
    history = []
    last = np.zeros(len(joints))
    scan = np.zeros(b["scan"]["dim"])
    if b["policy"]["uses_scan"]:
        raise SystemExit("this deployer feeds a flat ground's scandots only; "
                         "use `dreampolicy deploy-sim` for a scan policy")
    steps = max(1, round(a.seconds / t["control_dt"]))
    x0 = d.qpos[fq]
    err, fell_at, done = 0.0, None, 0
    for step in range(steps):
        quat = d.qpos[fq + 3:fq + 7].copy()
        r = quat_to_mat(quat)
        yaw = math.atan2(r[1, 0], r[0, 0])
        wz = np.clip(c["heading_stiffness"] * wrap(0.0 - yaw), *c["ang_vel_yaw"])
        command = np.array([a.speed, 0.0, wz])
        phase = 2 * math.pi * ((step * t["control_dt"] / c["gait_period_s"]) % 1.0)
        raw = {
            "base_ang_vel": (d.qvel[fv + 3:fv + 6], noise["ang_vel"]),
            "projected_gravity": (-r[2, :], noise["gravity"]),
            "dof_pos": (d.qpos[qadr] - default, noise["dof_pos"]),
            "dof_vel": (d.qvel[vadr], noise["dof_vel"]),
            "command": (command, 0.0),
            "last_action": (last, 0.0),
            "gait_phase": (np.array([math.sin(phase), math.cos(phase)]), 0.0),
        }
        obs = np.zeros(o["dim"])
        for f in o["fields"]:
            v, width = raw[f["name"]]
            s = np.array(f["scale"])
            x = np.clip(v * s, -o["clip"], o["clip"])
            if rng is not None and width > 0:
                x = np.clip(x + rng.uniform(-1, 1, f["len"]) * width * noise["level"] * s,
                            -o["clip"], o["clip"])
            obs[f["start"]:f["start"] + f["len"]] = x
        if not history:
            history = [obs.copy() for _ in range(k)]
        action = np.clip(policy(obs, history, scan), -clip, clip)
        if k:
            history = history[1:] + [obs.copy()]
        last = action
        d.ctrl[act] = default + scale * action
        for _ in range(t["decimation"]):
            mujoco.mj_step(m, d)
        done = step + 1
        err += math.hypot(d.qvel[fv] - command[0], d.qvel[fv + 1] - command[1])
        tilt = quat_to_mat(d.qpos[fq + 3:fq + 7])[2, 2] < math.cos(math.radians(FALL_TILT_DEG))
        if d.qpos[fq + 2] < FALL_HEIGHT or tilt:
            fell_at = done * t["control_dt"]
            break
    seconds = done * t["control_dt"]
    r = quat_to_mat(d.qpos[fq + 3:fq + 7])
    dist = float(d.qpos[fq] - x0)
    print(json.dumps({
        "deployer": "scripts/deploy_mujoco.py",
        "scene": scene,
        "mujoco_version": mujoco.__version__,
        "steps": done,
        "seconds": seconds,
        "distance_m": dist,
        "mean_forward_speed": dist / seconds,
        "commanded_speed": a.speed,
        "vel_tracking_error": err / max(done, 1),
        "final_yaw_deg": math.degrees(math.atan2(r[1, 0], r[0, 0])),
        "fell": fell_at is not None,
        "fell_at_s": fell_at,
        "observation_noise": rng is not None,
        "runtime": a.runtime,
    }))


if __name__ == "__main__":
    sys.exit(main())
