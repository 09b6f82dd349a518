#!/usr/bin/env bash
# The main job on the shipped samples: pose the body with every sample clip (animated glTF),
# validate the files, and render contact sheets. Outputs go to out/.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
bash scripts/setup.sh
cargo build --release --quiet
gb=target/release/garmentbake
mkdir -p out
for clip in 01_01 131_01 131_02; do
  $gb pose --body samples/body.glb --motion samples/motions/$clip.bvh --out out/${clip}_body.glb
  node tools/node/validate.mjs out/${clip}_body.glb
  $gb preview --body samples/body.glb --motion samples/motions/$clip.bvh --frames 6 --out out/${clip}_body.png
done
$gb preview --body samples/body.glb --garment samples/garments/skirt.obj --garment samples/garments/top.obj \
  --views front,side,back --out out/rest_garments.png
echo "outputs in out/: $(ls out | tr '\n' ' ')"
