#!/usr/bin/env bash
# Opt-in: Blender as a Python module (PyPI `bpy` 4.5 LTS, a 373 MB wheel, Python 3.11) in
# target/bpy-venv, for the slow test that imports our USD files into a real DCC
# (`cargo test --test integration slow_blender -- --ignored`). Idempotent.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
venv=target/bpy-venv
if [ -x "$venv/bin/python" ] && "$venv/bin/python" -c 'import bpy' >/dev/null 2>&1; then
  exit 0
fi
py="${GARMENTBAKE_PYTHON:-$HOME/.pyenv/versions/3.11.7/bin/python3.11}"
command -v "$py" >/dev/null 2>&1 || py=python3.11
mkdir -p target
"$py" -m venv "$venv"
"$venv/bin/pip" install -q --disable-pip-version-check bpy==4.5.4
