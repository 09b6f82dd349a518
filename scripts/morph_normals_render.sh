#!/usr/bin/env bash
# Before/after render of the bake's morph normals (docs/bake.md, "Morph normals"): the trained
# skirt baked on 131_02, drawn by three.js (the `view` page, headless Chromium) at one frame with
# the file's NORMAL deltas dropped (left: the baker before) and with them (right), side by side.
# Usage: bash scripts/morph_normals_render.sh [MODEL] [FRAME] [OUT.png]
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
model=${1:-runs/cov/skirt_c1.safetensors}
frame=${2:-150}
out=${3:-docs/img/morph_normals_before_after.png}
gb=${GB:-target/debug/garmentbake}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$gb" bake --model "$model" --motion samples/motions/131_02.bvh --fps 30 --tolerance-mm 1 \
    --out "$work/with.glb" --quiet >/dev/null
node tools/node/strip_morph_normals.mjs "$work/with.glb" "$work/without.glb" >/dev/null
for name in with without; do
    "$gb" view "$work/$name.glb" --out "$work/$name.html" --quiet >/dev/null
    chromium --headless --no-sandbox --disable-gpu --disable-dev-shm-usage --use-gl=swiftshader \
        --enable-unsafe-swiftshader --hide-scrollbars --force-device-scale-factor=1 \
        --host-resolver-rules="MAP * ~NOTFOUND" --virtual-time-budget=30000 --window-size=480,640 \
        --user-data-dir="$work/profile-$name" --screenshot="$work/$name.png" \
        "file://$work/$name.html#clip=131_02&frame=$frame&view=three-quarter&ui=0" 2>/dev/null
done
node tools/node/png_side_by_side.mjs "$out" "$work/without.png" "$work/with.png"
echo "wrote $out (frame $frame of 131_02, $model)"
