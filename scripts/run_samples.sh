#!/usr/bin/env bash
# The main job on the shipped samples: train the sample skirt briefly (PBNS, CPU), evaluate it on
# a clip it never saw, bake it to glTF and USD, and check the files. Outputs go to out/.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
bash scripts/setup.sh
cargo build --release --quiet
gb=target/release/garmentbake
mkdir -p out runs
epochs="${EPOCHS:-30}"

echo "== train the skirt ($epochs epochs; see docs/pbns.md for the full recipe)"
$gb train --body samples/body.glb --garment samples/garments/skirt.obj \
  --motion samples/motions/01_01.bvh --motion samples/motions/131_01.bvh \
  --epochs "$epochs" --seed 1 --out runs/skirt_quick.safetensors

echo "== evaluate on 131_02 (not trained on; the validation clip the recipes were chosen on): model vs plain LBS"
$gb eval --model runs/skirt_quick.safetensors --motion samples/motions/131_02.bvh --out out/131_02_skirt.pc2

echo "== bake (blend shapes within 1 mm of the network) to glTF and USD"
for out in out/skirt.glb out/skirt.usdc; do
  $gb bake --model runs/skirt_quick.safetensors --motion samples/motions/131_01.bvh \
    --motion samples/motions/131_02.bvh --tolerance-mm 1 --with-body --out "$out"
done
node tools/node/validate.mjs out/skirt.glb
.venv/bin/python tools/usd/check.py validate out/skirt.usdc

echo "== a production rig: a Character Creator take (cm, 99 joints, Z-up root, no T-pose) on the body"
$gb pose --body samples/body.glb --motion samples/motions/cc_base_002_01.bvh --out out/cc_base_002_01.glb
node tools/node/validate.mjs out/cc_base_002_01.glb

echo "== what the job made: the trained skirt on 131_02 beside plain LBS of the same skirt, and a page that plays the bake"
$gb preview --body samples/body.glb --motion samples/motions/131_02.bvh --model runs/skirt_quick.safetensors \
  --lbs --frame-count 6 --out out/131_02_skirt_vs_lbs.png
$gb view out/skirt.glb --out out/skirt.html
echo "outputs: $(cd out && ls | tr '\n' ' ')"
