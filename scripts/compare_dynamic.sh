#!/usr/bin/env bash
# The dynamic skirt against three perturbed simulations of a validation clip (issue 37's
# yardstick, docs/dynamic.md): each MODEL rolled out from the first simulated frame, then
# `garmentbake compare` with PBNS as the quasi-static baseline (own error b, e(k) restarted from
# the runs, the hem's swing beyond PBNS, strain, inside). The simulations and PBNS caches come
# from scripts/dynamic_set.sh and `eval` of the PBNS skirt (docs/pbns.md's recipe).
#
#   bash scripts/compare_dynamic.sh CLIP OUT_PREFIX NAME=MODEL.safetensors [NAME=MODEL ...]
#   e.g. bash scripts/compare_dynamic.sh 002_04 runs/cmp_002_04 linear=runs/dyn/linear.safetensors
#   NAME=eval:MODEL plays a PBNS or a swing (train-swing) with `eval` instead of `rollout`.
#   NO_HORIZON=1 leaves out e(k) (the restarts, most of the time): a quick look at b, hem, strain.
#
# CLIP is 131_02 (samples/motions) or a take of ../shared/data/mocap/cc_base; runs are read from
# runs/dynamic_set/CLIP_skirt_sim_p{0,1,2}.pc2 and PBNS from runs/dynamic_set/CLIP_pbns.pc2.
set -euo pipefail
cd "$(dirname "$0")/.."
CLIP=$1 OUT=$2
shift 2
GB=${GB:-target/debug/garmentbake}
D=${DIR:-runs/dynamic_set}
case $CLIP in
131_*) BVH=samples/motions/$CLIP.bvh ;;
*) BVH=../shared/data/mocap/cc_base/$CLIP.bvh ;;
esac
ARGS=()
for spec in "$@"; do
    name=${spec%%=*} model=${spec#*=}
    case $model in
    eval:*)
        # A PBNS (with or without a swing) has no state to restart from: played from the clip's
        # first frame by `eval`, as the PBNS baseline is.
        "$GB" eval --model "${model#eval:}" --motion "$BVH" --fps 30 --out "${OUT}_$name.pc2" \
            --quiet > "${OUT}_$name.txt"
        ARGS+=(--cache "$name=${OUT}_$name.pc2")
        ;;
    *)
        "$GB" rollout --model "$model" --motion "$BVH" --init "$D/${CLIP}_skirt_sim_p0.pc2" \
            --out "${OUT}_$name.pc2" --quiet > "${OUT}_$name.txt"
        ARGS+=(--cache "$name=${OUT}_$name.pc2")
        # e(k) restarts the model from the runs' states: most of compare's time.
        [ -n "${NO_HORIZON:-}" ] || ARGS+=(--model "$name=$model")
        ;;
    esac
done
"$GB" compare --body samples/body.glb --garment samples/garments/skirt.obj --motion "$BVH" --fps 30 \
    --sim "$D/${CLIP}_skirt_sim_p0.pc2" --sim "$D/${CLIP}_skirt_sim_p1.pc2" --sim "$D/${CLIP}_skirt_sim_p2.pc2" \
    "${ARGS[@]}" --cache "pbns=$D/${CLIP}_pbns.pc2" --baseline pbns \
    --plot-horizon "${OUT}_horizon.png" --plot-hem "${OUT}_hem.png" --json > "$OUT.json"
python3 - "$OUT.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
s = d["spread"]["sigma_mm"]
print(f"{sys.argv[1]}: {d['frames']} frames, runs' spread sigma {s['clip']:.1f} mm (first 50: {s['first_50']:.1f}); hem ceiling {d['hem']['mutual_correlation']:.2f}")
late = lambda l: "     -" if not l else f"{l['seconds']:+6.2f}"
print("runs' hem behind the others' mean (s): " + ", ".join(late(l).strip() for l in d["hem"].get("behind_the_others", [])))
print(f"{'cache':10} {'b clip':>7} {'b 50':>6} {'e1':>6} {'e10':>6} {'e25':>6} {'e50':>6} {'hem r':>6} {'amp':>5} {'late s':>6} {'strain':>7} {'p99':>6} {'inside':>7}")
for c in d["caches"]:
    own, hz, hem, p = c["score"]["own_mm"], c["horizon_mm"] or [], c["hem"], c["plausibility"]
    e = [f"{hz[k - 1]:6.1f}" if len(hz) >= k else "     -" for k in (1, 10, 25, 50)]
    r = hem["correlation_with_each"]
    print(f"{c['name']:10} {own['clip']:7.1f} {own['first_50']:6.1f} {' '.join(e)} {r if r is None else round(r, 2)!s:>6} {hem['amplitude_ratio']:5.2f} {late(hem.get('behind_the_runs'))} {p['strain_mean_pct']:6.1f}% {p['strain_p99_pct']:5.0f}% {c['inside_pct']:6.3f}%")
num = lambda x: "   -" if x is None else f"{x:4.2f}"
parts = d["hem"]["parts"]
print("hem parts, correlation (amplitude, behind the runs): " + " / ".join(q["part"] for q in parts))
print(f"{'runs':10} " + " / ".join(f"{num(q['mutual_correlation'])} ({q['amplitude_mm']:.0f} mm)" for q in parts))
for c in d["caches"]:
    print(f"{c['name']:10} " + " / ".join(f"{num(q['correlation_with_each'])} ({q['amplitude_ratio']:.2f}, {late(q.get('behind_the_runs')).strip()} s)" for q in c["hem"]["parts"]))
PY
