#!/usr/bin/env bash
# Behaviour check for refactors (issue 39: no output may change). Runs one garmentbake binary
# over the samples with short settings — the main job (train, eval, bake glTF / USD, pose the CC
# take, preview), previews with a model and with caches, view pages, a dynamic model (space,
# motion stage) rolled out, and a small batch — into OUT, then prints `sha256  file` for every
# output, sorted. Run it on the old and the new binary into the SAME folder (absolute paths end
# up in batch command lines) and diff the two listings.
#
# Not byte-compared, on purpose: a model file's metadata (it names the build that wrote it: the
# tensors are hashed instead), batch .key files, logs and job reports (keyed by the build; timings),
# and the simulation (Blender; the roll-out starts from a 6-frame one made once and kept in
# target/same_outputs_sim.pc2, so every run reads the same frames).
#
# Usage: bash scripts/same_outputs.sh BINARY OUT > listing.txt
#        bash scripts/same_outputs.sh --compare OLD_BINARY NEW_BINARY [OUT]   (exit 1 if any differ)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [[ ${1:-} == --compare ]]; then
  out=${4:-$root/target/same_outputs}
  bash "$0" "$2" "$out" > "$out.old.txt"
  bash "$0" "$3" "$out" > "$out.new.txt"
  diff "$out.old.txt" "$out.new.txt" && echo "same: $(wc -l < "$out.new.txt") outputs identical"
  exit
fi
gb=$(realpath "$1") out=$2
S=$root/samples M=$root/samples/motions
rm -rf "$out" && mkdir -p "$out" && out=$(realpath "$out")
cd "$root"
q() { "$gb" "$@" --quiet > /dev/null; }

# The main job (scripts/run_samples.sh), 4 epochs instead of 30.
q train --body $S/body.glb --garment $S/garments/skirt.obj --motion $M/01_01.bvh --motion $M/131_01.bvh \
  --epochs 4 --seed 1 --out "$out/skirt.safetensors"
q eval --model "$out/skirt.safetensors" --motion $M/131_02.bvh --out "$out/131_02_skirt.pc2" \
  --body-out "$out/131_02_body.pc2" --view "$out/131_02_eval.html"
for f in skirt.glb skirt.usdc; do
  q bake --model "$out/skirt.safetensors" --motion $M/131_01.bvh --motion $M/131_02.bvh \
    --tolerance-mm 1 --with-body --out "$out/$f"
done
q bake --model "$out/skirt.safetensors" --motion $M/131_02.bvh --max-targets 8 --out "$out/k8.glb" \
  --view "$out/k8.html"
q pose --body $S/body.glb --motion $M/cc_base_002_01.bvh --out "$out/cc_base_002_01.glb"
q preview --body $S/body.glb --motion $M/131_02.bvh --frames 6 --out "$out/131_02_body.png"

# Previews through the other paths of the panel layout, and the view page of a bake.
q preview --body $S/body.glb --motion $M/131_02.bvh --model "$out/skirt.safetensors" --lbs --frames 3 \
  --out "$out/131_02_model_lbs.png"
q preview --body $S/body.glb --garment $S/garments/skirt.obj --garment $S/garments/skirt.obj \
  --out "$out/rest.png"
q preview --body $S/body.glb --motion $M/131_02.bvh --garment $S/garments/skirt.obj \
  --garment $S/garments/skirt.obj --cache "$out/131_02_skirt.pc2" --cache "$out/131_02_skirt.pc2" \
  --side-by-side --frames 2 --out "$out/side_by_side.png"
q preview --body $S/body.glb --motion $M/131_02.bvh --garment $S/garments/skirt.obj \
  --cache "$out/131_02_skirt.pc2" --error-vs "$out/131_02_skirt.pc2" --frames 2 --out "$out/error_vs.png"
q view "$out/skirt.glb" --with "$out/131_02_skirt.pc2" --error-vs "$out/131_02_skirt.pc2" \
  --out "$out/skirt_view.html"

# A dynamic model on six simulated frames of 131_01: the linear space, the motion stage, roll-outs.
sim=$root/target/same_outputs_sim.pc2
if [[ ! -f $sim ]]; then
  q simulate --body $S/body.glb --garment $S/garments/skirt.obj --motion $M/131_01.bvh --fps 30 \
    --frames 6 --settle 0.1 --blend 0.2 --out "$sim"
fi
q train-dynamic --body $S/body.glb --garment $S/garments/skirt.obj --motion $M/131_01.bvh --sim "$sim" \
  --fps 30 --epochs 0 --batch 2 --threads 1 --out "$out/space.safetensors"
q train-dynamic --stage dynamic --from "$out/space.safetensors" --motion $M/131_01.bvh --sim "$sim" \
  --fps 30 --epochs 0 --ridge 1 --dynamics-epochs 2 --unroll-frames 2,3 --threads 1 \
  --out "$out/dynamic.safetensors"
q rollout --model "$out/dynamic.safetensors" --motion $M/131_01.bvh --init "$sim" --frames 6 --threads 1 \
  --reference "$sim" --out "$out/roll.pc2" --view "$out/roll.html" --lbs-out "$out/roll_lbs.pc2"
q rollout --model "$out/dynamic.safetensors" --motion $M/131_01.bvh --init "$sim" --frames 6 --threads 1 \
  --out "$out/roll.glb"

# A batch: the skirt's static recipe on two clips at 10 fps (no simulation).
cat > "$out/batch.toml" <<'TOML'
body = "SAMPLES/body.glb"
out = "OUT/batch"
threads = 1
[[clips]]
path = "SAMPLES/motions/131_0*.bvh"
fps = 10
[[garments]]
name = "skirt"
mesh = "SAMPLES/garments/skirt.obj"
seed = 0
[garments.static]
train = ["131_01"]
epochs = 2
args = ["--width", "16"]
cache = "pc2"
gltf = { max_targets = 8 }
TOML
sed -i "s|SAMPLES|$S|; s|OUT|$out|" "$out/batch.toml"
"$gb" batch plan "$out/batch.toml" --json > "$out/batch_plan.json"
q batch run "$out/batch.toml"

# The listing: tensors of model files, batch plans without their keys, every other file whole.
cd "$out"
python3 - <<'PY'
import hashlib, json, pathlib, struct
def tensors(b):
    n = struct.unpack("<Q", b[:8])[0]
    h = json.loads(b[8:8 + n]); h.pop("__metadata__", None); data = b[8 + n:]
    return json.dumps({k: (v["dtype"], v["shape"], hashlib.sha256(
        data[v["data_offsets"][0]:v["data_offsets"][1]]).hexdigest()) for k, v in sorted(h.items())})
def unkeyed(b):
    # Keys and the build id name the binary, not what it does.
    plan = json.loads(b); plan.pop("build", None); (plan.get("tools") or {}).pop("build", None)
    for j in plan.get("jobs", []):
        j.pop("key", None)
    return json.dumps(plan, sort_keys=True)
for p in sorted(pathlib.Path(".").rglob("*")):
    if not p.is_file() or p.suffix == ".key" or "logs" in p.parts or "reports" in p.parts:
        continue
    b = p.read_bytes()
    if p.suffix == ".safetensors":
        b, what = tensors(b).encode(), "tensors"
    elif p.name in ("plan.json", "batch_plan.json"):
        b, what = unkeyed(b).encode(), "unkeyed"
    else:
        what = "bytes"
    print(f"{hashlib.sha256(b).hexdigest()}  {what:<7}  {p}")
PY
