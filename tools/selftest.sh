#!/usr/bin/env bash
# Self-test of the independent-reader drivers, WITHOUT garmentbake:
# build analytic test files (tools/make_test_gltf.py), run the Khronos
# validator, three.js and Blender on them, compare with the analytic
# positions (tools/check_selftest.py).  Exit 0 = all readers agree.
#
# usage: tools/selftest.sh [OUTDIR]     (default: a fresh temp dir, kept)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
tools="$root/tools"
py="${GARMENTBAKE_PYTHON:-$root/.venv/bin/python}"
[ -x "$py" ] || py=python3
out="${1:-$(mktemp -d /tmp/garmentbake-selftest.XXXXXX)}"
mkdir -p "$out"
export BIG_RINGS=3300 # 13200 vertices: the timing case from the brief
blender=(blender -b --factory-startup --python-exit-code 1)
log() { printf '\n== %s\n' "$*"; }
timed() { local s; s=$(date +%s%N); "$@"; echo "   (wall $(( ($(date +%s%N) - s) / 1000000 )) ms: $*)"; }

log "inputs -> $out"
"$py" "$tools/make_test_gltf.py" "$out" --big-rings "$BIG_RINGS"

log "Khronos glTF-Validator"
for f in bar.glb bar_split.glb bar_ext.gltf big.glb; do
  node "$tools/node/validate.mjs" "$out/$f"
done
# negative control: an invalid file must be rejected (exit 1)
if node "$tools/node/validate.mjs" "$out/bar_bad.glb" 2>/dev/null; then
  echo "FAIL: validator accepted bar_bad.glb"; exit 1
else
  echo "ok: bar_bad.glb rejected as expected"
fi

log "three.js GLTFLoader + AnimationMixer (CPU skinning/morphs)"
times=0,0.25,0.5,0.51,0.777,1 # 0.51 / 0.777 fall between keys: checks LINEAR
node "$tools/node/skin_eval.mjs" "$out/bar.glb" --times "$times" --out "$out/three_bar.json"
node "$tools/node/skin_eval.mjs" "$out/bar_split.glb" --times "$times" --out "$out/three_split.json"
node "$tools/node/skin_eval.mjs" "$out/bar_ext.gltf" --times "$times" --mesh Bar --out "$out/three_ext.json"
timed node "$tools/node/skin_eval.mjs" "$out/big.glb" --times 0,0.1,0.2,0.3,0.4,0.5,0.6,0.7,0.8,1 --out "$out/three_big.json"

log "Blender glTF importer (depsgraph-evaluated meshes)"
"${blender[@]}" --python "$tools/blender/eval_gltf.py" -- "$out/bar.glb" --frames 0,1,7,15,22,30 --out "$out/blender_bar.json" >"$out/blender_bar.log" 2>&1 || { cat "$out/blender_bar.log"; exit 1; }
"${blender[@]}" --python "$tools/blender/eval_gltf.py" -- "$out/bar_split.glb" --times 0,0.5,1 --out "$out/blender_split.json" >"$out/blender_split.log" 2>&1 || { cat "$out/blender_split.log"; exit 1; }
# Blender's factory 24 fps: keys land on fractional frames, t=0.51 -> frame 12.24
"${blender[@]}" --python "$tools/blender/eval_gltf.py" -- "$out/bar.glb" --fps 24 --times 0,0.51,0.75,1 --out "$out/blender_bar_fps24.json" >"$out/blender_fps24.log" 2>&1 || { cat "$out/blender_fps24.log"; exit 1; }
grep -h '^eval_gltf' "$out"/blender_*.log

log "Blender OBJ + Mesh Cache (PC2)"
"${blender[@]}" --python "$tools/blender/eval_pc2.py" -- "$out/cloth.obj" "$out/cloth.pc2" --frames 0,1,2.5,4,6 --out "$out/blender_pc2.json" >"$out/blender_pc2.log" 2>&1 || { cat "$out/blender_pc2.log"; exit 1; }
grep -h '^eval_pc2' "$out/blender_pc2.log"

log "compare with analytic positions"
"$py" "$tools/check_selftest.py" "$out"
