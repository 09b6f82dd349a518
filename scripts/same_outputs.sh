#!/usr/bin/env bash
# Behaviour check for refactors: runs the same short pipeline (train the sample skirt 8 epochs with
# --seed 1, eval on 131_02, bake glTF / USD / 8 targets) with two garmentbake binaries and
# compares the results: model tensors (the metadata may differ), caches and bakes byte for byte.
# Usage: bash scripts/same_outputs.sh OLD_BINARY NEW_BINARY [WORK_DIR]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
old=$1 new=$2 work=${3:-$root/target/same_outputs}
S=$root/samples
run() { # binary, output folder
  local gb=$1 out=$2
  rm -rf "$out" && mkdir -p "$out"
  "$gb" train --body $S/body.glb --garment $S/garments/skirt.obj --motion $S/motions/01_01.bvh \
    --motion $S/motions/131_01.bvh --epochs 8 --seed 1 --out "$out/skirt.safetensors" > "$out/train.txt"
  "$gb" eval --model "$out/skirt.safetensors" --motion $S/motions/131_02.bvh --out "$out/131_02.pc2" > /dev/null
  for f in skirt.glb skirt.usda; do
    "$gb" bake --model "$out/skirt.safetensors" --motion $S/motions/131_01.bvh --motion $S/motions/131_02.bvh \
      --tolerance-mm 1 --with-body --out "$out/$f" > /dev/null
  done
  "$gb" bake --model "$out/skirt.safetensors" --motion $S/motions/131_02.bvh --max-targets 8 --out "$out/k8.glb" > /dev/null
}
run "$old" "$work/old"
run "$new" "$work/new"
python3 - "$work/old" "$work/new" <<'PY'
import hashlib, json, struct, sys
def tensors(p):
    b = open(p, "rb").read()
    n = struct.unpack("<Q", b[:8])[0]
    h = json.loads(b[8:8 + n]); h.pop("__metadata__", None); data = b[8 + n:]
    return {k: (v["dtype"], v["shape"], hashlib.sha256(data[v["data_offsets"][0]:v["data_offsets"][1]]).hexdigest())
            for k, v in sorted(h.items())}
old, new = sys.argv[1:]
same = True
for f in ["skirt.safetensors", "skirt.ckpt.safetensors"]:
    a, b = tensors(f"{old}/{f}"), tensors(f"{new}/{f}")
    digest = hashlib.sha256(json.dumps(a, sort_keys=True).encode()).hexdigest()[:16]
    print(f"{f}: {len(a)} tensors {'identical' if a == b else 'DIFFER'} (digest {digest})")
    same &= a == b
for f in ["131_02.pc2", "skirt.glb", "skirt.usda", "k8.glb"]:
    a, b = (hashlib.sha256(open(f"{d}/{f}", "rb").read()).hexdigest() for d in (old, new))
    print(f"{f}: {'identical' if a == b else 'DIFFER'} ({a[:16]})")
    same &= a == b
sys.exit(0 if same else 1)
PY
