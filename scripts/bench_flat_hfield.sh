#!/usr/bin/env bash
# How the ground's representation costs physics: the same 16 standing G1s on a
# plane; on an all-flat map whose Flat-column envs step on a plane
# (env.terrain.flat_on_plane, the default); and on the same map as a heightfield
# with no roughness, with the 5 mm roughness floor, and with 2 cm roughness, at
# 0.05 m and 0.1 m resolution.
# Prints one JSON line per variant (bench env's keys plus the variant).
# Usage: scripts/bench_flat_hfield.sh [path/to/dreampolicy]
set -euo pipefail
BIN="${1:-target/release/dreampolicy}"
cd "$(dirname "$0")/.."
common=(--json --steps 100 --rounds 3 --set env.domain_rand.enabled=false)
run() {
  local label="$1"; shift
  "$BIN" bench env "${common[@]}" "$@" |
    python3 -c "import json,sys; d=json.load(sys.stdin); d['variant']='$label'; print(json.dumps({k: d[k] for k in ['variant','mujoco_version','raw_physics_steps_per_s','contacts_per_env']}))"
}
run plane --config configs/flat_small.yaml
run "flat tiles on plane" --config configs/terrain_small.yaml --set 'env.terrain.map.kinds={flat: 1.0}'
for hs in 0.05 0.1; do
  for r in 0.0 0.005 0.02; do
    run "hfield hs=$hs rough=$r" --config configs/terrain_small.yaml \
      --set 'env.terrain.map.kinds={flat: 1.0}' --set env.terrain.map.base_roughness=0 \
      --set env.terrain.map.min_roughness=$r --set env.terrain.map.horizontal_scale=$hs \
      --set env.terrain.flat_on_plane=false
  done
done
