#!/usr/bin/env bash
# Copy a training run into models/checkpoints/<name>/ so that it lands in git,
# laid out as a run directory: config.yaml, metrics.csv, log.txt,
# plots/training.png, checkpoints/latest.pt, plus eval.json from
# `dreampolicy eval --full-collision` (100 lanes of TERRAIN, flat by default). The run
# continues from the copy with
#   cp -r models/checkpoints/<name> runs/<name>
#   target/release/dreampolicy train specialist --resume runs/<name>
# Usage: scripts/package_checkpoint.sh RUN_DIR NAME [EPISODES] [TERRAIN]
set -euo pipefail
run="$1"; name="$2"; episodes="${3:-100}"; terrain="${4:-flat}"
cd "$(dirname "$0")/.."
BIN=target/release/dreampolicy
out="models/checkpoints/$name"
mkdir -p "$out/checkpoints" "$out/plots"
cp "$run/checkpoints/latest.pt" "$out/checkpoints/latest.pt"
cp "$run/config.yaml" "$run/metrics.csv" "$run/log.txt" "$out/"
"$BIN" plot "$out" >/dev/null
"$BIN" eval --checkpoint "$out/checkpoints/latest.pt" --terrains "$terrain" --episodes "$episodes" \
  --full-collision --threads 2 --out "$out/eval.json"
echo "packaged $run into $out"
