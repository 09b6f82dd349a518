#!/usr/bin/env bash
# The bake table of docs/bake.md: replay error (vs the network) and file size for
# K ∈ {8, 16, 32, 64, full} × influences {4, 8} on a clip.
# usage: scripts/bake_table.sh MODEL.safetensors [CLIP.bvh]   (release build, writes under out/table/)
set -euo pipefail
model="$1"; clip="${2:-samples/motions/131_02.bvh}"
gb=target/release/garmentbake
mkdir -p out/table
echo "| targets | influences | max error (mm) | mean error (mm) | pruning alone (mm) | file (MB) | bake (s) |"
echo "|---|---|---|---|---|---|---|"
for inf in 4 8; do
  for k in 8 16 32 64 full; do
    args=(); [ "$k" = full ] || args=(--max-targets "$k")
    out="out/table/k${k}_i${inf}.glb"
    start=$(date +%s%N)
    json=$($gb bake --model "$model" --motion "$clip" --influences "$inf" "${args[@]}" --out "$out" --json)
    ms=$(( ($(date +%s%N) - start) / 1000000 ))
    echo "$json" | python3 -c "
import json,sys
r=json.load(sys.stdin); c=r['report']['clips'][0]; p=c['pruning_error_mm']
print('| %s (%d) | %d | %.3f | %.4f | %s | %.2f | %.2f |' % ('$k', r['report']['targets'], r['report']['influences'], c['max_mm'], c['mean_mm'], '%.1f' % p if p is not None else '-', r['bytes']/1e6, $ms/1000.0))"
  done
done
