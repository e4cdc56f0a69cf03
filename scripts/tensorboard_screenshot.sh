#!/usr/bin/env bash
# A PNG of TensorBoard's scalars page for one run directory, from a headless
# browser: the README's screenshot. Not part of setup or CI (TensorBoard and
# Chromium are large); it needs `tensorboard` on PATH or TENSORBOARD=... (e.g. a
# venv: python3 -m venv /tmp/tbv && /tmp/tbv/bin/pip install tensorboard) and
# Debian's chromium (apt-get install chromium).
#
#   bash scripts/tensorboard_screenshot.sh runs/bridge out.png [TAG_REGEX]
set -euo pipefail
run="${1:?usage: tensorboard_screenshot.sh RUN_DIR OUT.png [TAG_REGEX]}"
out="${2:?usage: tensorboard_screenshot.sh RUN_DIR OUT.png [TAG_REGEX]}"
tags="${3:-terrain_level|mean_reward|clip_fraction|total_fps|mean_episode_length|vel_error_xy}"
tb="${TENSORBOARD:-tensorboard}"
port="${PORT:-6123}"
logdir="$(mktemp -d)"
trap 'kill $tb_pid 2>/dev/null || true; rm -rf "$logdir"' EXIT
name="$(basename "$run")"
mkdir -p "$logdir/$name"
cp "$run"/events.out.tfevents.* "$logdir/$name/"
"$tb" --logdir "$logdir" --port "$port" >/dev/null 2>&1 &
tb_pid=$!
for _ in $(seq 60); do
  curl -sf "localhost:$port/data/runs" | grep -q "$name" && break
  sleep 1
done
filter="$(python3 -c 'import sys, urllib.parse; print(urllib.parse.quote(sys.argv[1]))' "$tags")"
chromium --headless --no-sandbox --disable-gpu --hide-scrollbars --window-size=1500,1050 \
  --virtual-time-budget=60000 --screenshot="$out" \
  "http://localhost:$port/?darkMode=false#scalars&tagFilter=$filter" 2>/dev/null
echo "$out"
