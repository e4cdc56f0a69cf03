#!/usr/bin/env python3
"""Check that a G1 scene file stands on its own in stock MuJoCo (the `mujoco` Python
package, no dreampolicy loader): reset to the `stand` keyframe, hold its ctrl for 10 s,
and require the pelvis height to stay within 5 cm of its start and the pelvis within
10 cm horizontally (as tests/g1.rs does in Rust; the pose leans forward ~5 cm at first).

Optional: skips with a message (exit 0) when `mujoco` is not importable; nothing is
installed. Usage: python3 scripts/check_stock_mujoco.py [scene.xml]
(default models/g1/scene_flat.xml). Exit 1 when the robot does not stand.
"""
import sys
from pathlib import Path

SECONDS, MAX_DZ, MAX_DXY = 10.0, 0.05, 0.10


def main():
    try:
        import mujoco
    except ImportError:
        print("check_stock_mujoco.py: the mujoco Python package is not importable; skipped")
        return 0
    root = Path(__file__).resolve().parent.parent
    scene = Path(sys.argv[1]) if len(sys.argv) > 1 else root / "models/g1/scene_flat.xml"
    m = mujoco.MjModel.from_xml_path(str(scene))
    d = mujoco.MjData(m)
    key = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "stand")
    pelvis = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "pelvis")
    if key < 0 or pelvis < 0:
        print(f"{scene}: no keyframe 'stand' or body 'pelvis'")
        return 1
    mujoco.mj_resetDataKeyframe(m, d, key)
    mujoco.mj_forward(m, d)
    start = d.xpos[pelvis].copy()
    dz = dxy = 0.0
    for _ in range(round(SECONDS / m.opt.timestep)):
        d.ctrl[:] = m.key_ctrl[key]
        mujoco.mj_step(m, d)
        off = d.xpos[pelvis] - start
        dz = max(dz, abs(float(off[2])))
        dxy = max(dxy, float(off[0] ** 2 + off[1] ** 2) ** 0.5)
    armed = int((m.dof_armature > 0).sum())
    ok = dz < MAX_DZ and dxy < MAX_DXY
    print(
        f"MuJoCo {mujoco.__version__}, {scene.name}: {armed} dofs with armature; in {SECONDS:.0f} s "
        f"the pelvis moved at most {dz:.4f} m vertically (limit {MAX_DZ}), {dxy:.4f} m "
        f"horizontally (limit {MAX_DXY}): {'ok' if ok else 'FAILED'}"
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
