#!/usr/bin/env bash
# Copy a world-model sweep's directory (runs/sweeps/<name>) into
# models/sweeps/<name>/ so that it lands in git and resumes from there: the
# sweep's sweep.yaml and runs.json, and for each run its config.yaml,
# metrics.csv, log.txt, plots/ and result.json; a finished run (result.json
# written) keeps its inference copy (`dreampolicy checkpoint strip`: the EMA
# denoiser and normalization, a quarter of the size) as
# checkpoints/latest.pt, a run in progress its full resume checkpoint; a run
# not started is left out. The sweep goes on from the copy with
#   mkdir -p runs/sweeps && cp -r models/sweeps/<name> runs/sweeps/
#   dreampolicy sweep run configs/sweeps/<name>.yaml --jobs 2
# (a finished run is skipped by its result.json; its stripped checkpoint is
# enough to plan with, not to train on).
# Usage: scripts/package_sweep.sh NAME [RUNS_ROOT]
set -euo pipefail
name="$1"; root="${2:-runs/sweeps}"
cd "$(dirname "$0")/.."
BIN=target/release/dreampolicy
src="$root/$name"; out="models/sweeps/$name"
[ -f "$src/sweep.yaml" ] || { echo "no sweep at $src (sweep.yaml missing)" >&2; exit 1; }
mkdir -p "$out"
cp "$src/sweep.yaml" "$src/runs.json" "$out/"
for run in "$src"/[0-9][0-9][0-9]-*/; do
  run="${run%/}"; r="$(basename "$run")"
  [ -f "$run/checkpoints/latest.pt" ] || continue
  mkdir -p "$out/$r/checkpoints"
  cp "$run/config.yaml" "$run/metrics.csv" "$run/log.txt" "$out/$r/"
  [ -d "$run/plots" ] && cp -r "$run/plots" "$out/$r/"
  if [ -f "$run/result.json" ]; then
    cp "$run/result.json" "$out/$r/"
    # a run copied back from models/sweeps/ already holds its inference copy
    "$BIN" checkpoint strip --if-needed --out "$out/$r/checkpoints/latest.pt" "$run/checkpoints/latest.pt" >/dev/null
    echo "$r: finished, inference copy"
  else
    rm -f "$out/$r/result.json"
    cp "$run/checkpoints/latest.pt" "$out/$r/checkpoints/latest.pt"
    echo "$r: in progress, resume checkpoint"
  fi
done
echo "packaged $src into $out"
