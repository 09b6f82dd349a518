#!/usr/bin/env bash
# Device check: PBNS training throughput on the GPU vs CPU, with that machine's libtorch.
set -u
T=$(python3 -c 'import torch,os;print(os.path.dirname(torch.__file__))')/lib
export LD_LIBRARY_PATH=$T:${LD_LIBRARY_PATH:-}
nvidia-smi --query-gpu=name,memory.total --format=csv,noheader
python3 -c 'import torch;print("torch", torch.__version__, "cuda", torch.version.cuda)'
G=gpu/garmentbake
ldd $G | grep -E "torch|cuda" | head
IN="--body samples/body.glb --garment samples/garments/skirt.obj --motion samples/motions/01_01.bvh --motion samples/motions/131_01.bvh"
for garment in skirt top; do
  IN="--body samples/body.glb --garment samples/garments/$garment.obj --motion samples/motions/01_01.bvh --motion samples/motions/131_01.bvh"
  echo "== $garment cuda (candidate refresh on the device)"; timeout 120 $G bench train $IN --device cuda --json
  echo "== $garment cuda, refresh by CPU k-d trees"; timeout 120 $G bench train $IN --device cuda --refresh trees --json
  echo "== $garment cuda batch 64"; timeout 120 $G bench train $IN --device cuda --batch 64 --json
  echo "== $garment cpu 16 threads"; timeout 120 $G bench train $IN --device cpu --threads 16 --json
done
echo "== train the top (last garment above) 10 epochs on cuda"
/usr/bin/time -f "%e s wall" timeout 200 $G train $IN --epochs 10 --device cuda --seed 1 --out $OUT/skirt_gpu.safetensors 2>&1 | tail -6
