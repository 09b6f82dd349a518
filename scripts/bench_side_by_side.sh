#!/usr/bin/env bash
# `garmentbake bench train` of two binaries alternated in one run, on the skirt recipe's inputs:
# on a shared, noisy machine only ratios measured side by side compare (docs/pbns.md, Speed).
# usage: scripts/bench_side_by_side.sh OLD_BINARY NEW_BINARY [ROUNDS] [extra bench args...]
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
old=$1 new=$2 rounds=${3:-2}
shift $(($# < 3 ? $# : 3))
args=(bench train --body samples/body.glb --garment samples/garments/skirt.obj
  --motion samples/motions/01_01.bvh --motion samples/motions/131_01.bvh --json "$@")
for _ in $(seq "$rounds"); do
  for b in "$old" "$new"; do
    "$b" "${args[@]}" | B="$b" python3 -c '
import json, os, sys
d = json.load(sys.stdin); s = d["split"]
step = 1e3 * s["seconds"] / d["steps"]
print("%-28s %6.1f poses/s %6.1f ms/step (%5.1f without the refresh) forward %4.1f %% losses %4.1f %% nearest %4.1f %% (refresh %4.1f %%) backward+Adam %4.1f %%"
      % (os.environ["B"][-28:], d["poses_per_s"], step, step * (1 - s["nearest_refresh_pct"] / 100),
         s["forward_pct"], s["losses_pct"], s["nearest_pct"], s["nearest_refresh_pct"], s["backward_pct"]))'
  done
done
