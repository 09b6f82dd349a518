#!/usr/bin/env bash
# More simulated training clips for the dynamic skirt from the two shipped training clips
# (01_01, 131_01; 131_02 is held out and never used): 11 takes made by scripts/augment_bvh.py
# (mirrored, re-timed, reversed, swayed), each simulated by `garmentbake simulate`, and the
# `--motion/--sim` arguments of all 13 clips written for `train-dynamic` (docs/dynamic.md,
# "More simulated clips" and "Swayed and reversed takes").
#
#   bash scripts/skirt_takes.sh [DIR]          # DIR defaults to runs/takes
#   garmentbake train-dynamic --body samples/body.glb --garment samples/garments/skirt.obj \
#       $(cat runs/takes/motions.txt) --fps 30 --epochs 0 --latent 128 --out runs/takes_space.safetensors
#
# `simulate` caches by the hash of its inputs (runs/sim), so a second run reads every take back in
# a second and a take whose BVH changed is simulated again. About 0.6–0.9 s per frame on 2
# cores, 3,900 frames in all: roughly 45 minutes the first time.
set -euo pipefail
cd "$(dirname "$0")/.."
DIR=${1:-runs/takes}
GB=${GB:-target/release/garmentbake}
[ -x "$GB" ] || cargo build --release
mkdir -p "$DIR"
M=samples/motions
# name  source  augment_bvh.py flags
TAKES="
131_01_m        131_01 --mirror
131_01_s125     131_01 --speed 1.25
131_01_s08      131_01 --speed 0.8
131_01_m_s125   131_01 --mirror --speed 1.25
01_01_m         01_01  --mirror
131_01_w1       131_01 --sway 1
131_01_mw2      131_01 --mirror --sway 2
131_01_r        131_01 --reverse
01_01_w3        01_01  --sway 3
01_01_rw4       01_01  --reverse --sway 4
131_01_s125w5   131_01 --speed 1.25 --sway 5
"
ARGS="--motion $M/01_01.bvh --sim runs/01_01_skirt_sim.pc2 --motion $M/131_01.bvh --sim runs/131_01_skirt_sim.pc2"
for clip in 01_01 131_01; do
    "$GB" simulate --body samples/body.glb \
        --garment samples/garments/skirt.obj --motion $M/$clip.bvh --fps 30 --out runs/${clip}_skirt_sim.pc2
done
while read -r name source flags; do
    [ -n "$name" ] || continue
    # shellcheck disable=SC2086  # the flags are words
    python3 scripts/augment_bvh.py $M/$source.bvh "$DIR/$name.bvh" $flags
    "$GB" simulate --body samples/body.glb \
        --garment samples/garments/skirt.obj --motion "$DIR/$name.bvh" --fps 30 \
        --out "$DIR/${name}_skirt_sim.pc2"
    ARGS="$ARGS --motion $DIR/$name.bvh --sim $DIR/${name}_skirt_sim.pc2"
done <<< "$TAKES"
echo "$ARGS" > "$DIR/motions.txt"
echo "wrote $DIR/motions.txt (13 clips: 01_01, 131_01 and 11 takes)"
