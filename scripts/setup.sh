#!/usr/bin/env bash
# dreampolicy: one-command setup on a fresh Debian 12 machine. Idempotent: a
# second run checks what is there and only redoes what is missing.
#
#   1. Debian packages: libmujoco-dev (MuJoCo 2.2.2), clang/libclang (bindgen), unzip, python3-pip,
#      python3-venv, fonts-dejavu-core (the TrueType font of the training-curve PNGs, src/plot.rs),
#      libosmesa6 and ffmpeg (`dreampolicy render`: headless OpenGL for MuJoCo's renderer, and
#      the video encoder)
#   2. Registry wheels pinned by hash (scripts/wheels.lock), unpacked, never imported:
#        third_party/libtorch/torch      libtorch 2.13 for tch 0.26 (+ nvidia/ runtime libs)
#        third_party/mujoco-3.3.7        MuJoCo 3.3.7 headers + library (MUJOCO_DIR build)
#        models/unitree_g1               the Unitree G1 29-DOF MJCF + meshes (from mjlab)
#      and models/unitree_g1/g1_armature.xml: the vendor g1.xml with joint armature from
#      models/g1/armature.txt (scripts/g1_armature.py; rewritten only when stale)
#   3. The reference Python MCAP reader of CI's cross-language checks: mcap, zstandard, lz4
#      pinned by hash (scripts/python.lock) in the venv third_party/pyenv (Debian 12's
#      pip refuses global installs); reinstalled when the lock file changes
#   4. cargo build --release
#
# Env: SKIP_BUILD=1 skips step 4; DREAMPOLICY_WHEEL_CACHE=<dir> reuses downloaded wheels.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
log() { printf '[setup] %s\n' "$*"; }

# --- 1. Debian packages -------------------------------------------------------
APT_PKGS=(libmujoco-dev libclang-dev clang pkg-config unzip python3 python3-pip python3-venv ca-certificates curl build-essential fonts-dejavu-core libosmesa6 ffmpeg)
missing=()
for p in "${APT_PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  log "apt-get install ${missing[*]}"
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q "${missing[@]}"
else
  log "Debian packages present"
fi

if ! command -v cargo >/dev/null 2>&1; then
  if [ -x "$HOME/.cargo/bin/cargo" ]; then
    export PATH="$HOME/.cargo/bin:$PATH"
  else
    log "installing the Rust toolchain with rustup (stable)"
    curl --proto '=https' --tlsv1.2 -sSf https://sh.rustup.rs | sh -s -- -y --profile minimal -c rustfmt,clippy
    export PATH="$HOME/.cargo/bin:$PATH"
  fi
fi

# --- 2. Pinned wheels -----------------------------------------------------------
PY=python3
command -v "$PY" >/dev/null || { echo "python3 not found" >&2; exit 1; }
WHEELS="${DREAMPOLICY_WHEEL_CACHE:-$ROOT/third_party/wheels}"
mkdir -p "$WHEELS"

need_wheels=0
[ -f third_party/libtorch/.done ] || need_wheels=1
[ -f third_party/mujoco-3.3.7/.done ] || need_wheels=1
[ -f models/unitree_g1/.done ] || need_wheels=1
if ((need_wheels)); then
  log "pip download (hash-checked) into $WHEELS"
  # --platform/--python-version make the choice independent of the local Python;
  # pip matches manylinux tags exactly, so list the ones the pinned wheels carry.
  "$PY" -m pip download --quiet --no-deps --only-binary=:all: --require-hashes \
    --python-version 3.11 --implementation cp --abi cp311 --abi none --abi abi3 \
    --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 \
    --platform manylinux_2_25_x86_64 --platform manylinux_2_17_x86_64 \
    --platform manylinux2014_x86_64 --platform any \
    -r scripts/wheels.lock -d "$WHEELS"
fi

wheel() { ls "$WHEELS"/"$1"-*.whl 2>/dev/null | head -n1; }

if [ ! -f third_party/libtorch/.done ]; then
  log "unpacking libtorch"
  rm -rf third_party/libtorch && mkdir -p third_party/libtorch
  unzip -q "$(wheel torch-2.13.0)" 'torch/lib/*' 'torch/include/*' 'torch/share/*' 'torch/version.py' -d third_party/libtorch
  # torch's libraries find these through their rpath $ORIGIN/../../nvidia/*/lib.
  unzip -q "$(wheel nvidia_cuda_runtime-13.0.96)" 'nvidia/*' -d third_party/libtorch
  unzip -q "$(wheel nvidia_cuda_cupti-13.0.85)" 'nvidia/*' -d third_party/libtorch
  touch third_party/libtorch/.done
fi

if [ ! -f third_party/mujoco-3.3.7/.done ]; then
  log "unpacking MuJoCo 3.3.7"
  tmp="$(mktemp -d)"
  unzip -q "$(wheel mujoco-3.3.7)" 'mujoco/libmujoco.so.3.3.7' 'mujoco/include/*' -d "$tmp"
  rm -rf third_party/mujoco-3.3.7 && mkdir -p third_party/mujoco-3.3.7/lib
  mv "$tmp/mujoco/include" third_party/mujoco-3.3.7/include
  mv "$tmp/mujoco/libmujoco.so.3.3.7" third_party/mujoco-3.3.7/lib/
  rm -rf "$tmp"
  touch third_party/mujoco-3.3.7/.done
fi

if [ ! -f models/unitree_g1/.done ]; then
  log "unpacking the Unitree G1 description (mjlab 1.6.0)"
  tmp="$(mktemp -d)"
  unzip -q "$(wheel mjlab-1.6.0)" 'mjlab/asset_zoo/robots/unitree_g1/xmls/*' -d "$tmp"
  rm -rf models/unitree_g1
  mv "$tmp/mjlab/asset_zoo/robots/unitree_g1/xmls" models/unitree_g1
  rm -rf "$tmp"
  (cd models/unitree_g1 && sha256sum -c --quiet "$ROOT/models/g1/vendor.sha256")
  touch models/unitree_g1/.done
fi
# every run: regenerates the file if it is missing or differs from what the table gives
"$PY" scripts/g1_armature.py

# --- 3. Python reference readers (venv) ----------------------------------------
PYENV="$ROOT/third_party/pyenv"
if ! cmp -s scripts/python.lock "$PYENV/.done"; then
  log "venv third_party/pyenv: pip install (hash-checked) scripts/python.lock"
  rm -rf "$PYENV"
  "$PY" -m venv "$PYENV"
  "$PYENV/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps \
    --only-binary=:all: --require-hashes -r scripts/python.lock
  cp scripts/python.lock "$PYENV/.done"
else
  log "venv third_party/pyenv up to date"
fi

# --- 4. Build -------------------------------------------------------------------
if [ "${SKIP_BUILD:-0}" != "1" ]; then
  log "cargo build --release"
  cargo build --release --workspace --all-targets
fi
log "done: target/release/dreampolicy info"
