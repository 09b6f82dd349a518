#!/usr/bin/env bash
# Idempotent set-up: Debian packages, project venv (libtorch + usd-core + alembic3d + ray), npm validators.
# Fast when already done: every step checks before it installs.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
log() { printf '[setup] %s\n' "$*" >&2; }

# 1. Debian packages for the independent client checks (Blender imports our files, Chromium
#    plays our pages).
need_apt=()
command -v blender >/dev/null 2>&1 || need_apt+=(blender)
python3 -c 'import numpy' >/dev/null 2>&1 || dpkg -s python3-numpy >/dev/null 2>&1 || need_apt+=(python3-numpy)
command -v node >/dev/null 2>&1 || need_apt+=(nodejs npm)
command -v cc >/dev/null 2>&1 || need_apt+=(build-essential)
# Headless Chromium (SwiftShader WebGL, no GPU) opens the pages `garmentbake view` writes.
command -v chromium >/dev/null 2>&1 || need_apt+=(chromium)
if [ ${#need_apt[@]} -gt 0 ]; then
  log "apt-get install ${need_apt[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${need_apt[@]}" >/dev/null
fi

# 2. Python venv: CPU-usable libtorch 2.11 (slim, no CUDA wheels beyond what libtorch_cpu links) + usd-core.
py="${GARMENTBAKE_PYTHON:-}"
if [ -z "$py" ]; then
  for c in "$HOME/.pyenv/versions/3.11.7/bin/python3.11" python3.11 python3; do
    if command -v "$c" >/dev/null 2>&1; then py="$(command -v "$c")"; break; fi
  done
fi
if [ ! -x .venv/bin/python ]; then
  log "creating .venv with $py"
  "$py" -m venv .venv
fi
if [ ! -f .venv/lib/python3.11/site-packages/torch/lib/libtorch_cpu.so ] || ! .venv/bin/python -c 'import pxr, numpy' >/dev/null 2>&1; then
  log "pip install torch==2.11.0 (libtorch), usd-core, numpy"
  .venv/bin/pip install -q --disable-pip-version-check --no-deps \
    torch==2.11.0 nvidia-cuda-runtime==13.0.96 nvidia-cuda-cupti==13.0.85
  .venv/bin/pip install -q --disable-pip-version-check usd-core==26.11 numpy
fi

# 2a. PyAlembic (PyPI `alembic3d`, one 13 MB manylinux wheel): the `.abc` point-cache writer
#     (python_bridge/src/abc_writer.py) and tools/abc/read.py.
if ! .venv/bin/python -c 'import alembic3d' >/dev/null 2>&1; then
  log "pip install alembic3d==1.8.12.1"
  .venv/bin/pip install -q --disable-pip-version-check alembic3d==1.8.12.1
fi

# 2b. Ray (PyPI `ray`, one 79 MB wheel + small pure-Python deps, ~40 s): the engine of
#     `garmentbake batch run --ray` and of its test (a local head node). The local runner needs nothing.
if [ ! -x .venv/bin/ray ]; then
  log "pip install ray==2.60.0"
  .venv/bin/pip install -q --disable-pip-version-check ray==2.60.0
fi

# 3. npm tools used by tests: Khronos glTF validator, three.js (GLTFLoader in Node), gltfpack,
#    pngjs (16-bit PNG of vertex animation textures).
if [ ! -d tools/node/node_modules/gltf-validator ] || [ ! -d tools/node/node_modules/three ] \
  || [ ! -d tools/node/node_modules/gltfpack ] || [ ! -d tools/node/node_modules/pngjs ]; then
  log "npm install (tools/node)"
  (cd tools/node && npm install --silent --no-audit --no-fund >/dev/null)
fi

# 4. Cargo environment: LIBTORCH / PYO3_PYTHON point at the venv (see .cargo/config.toml).
log "ready"
