#!/usr/bin/env python3
"""Compare the readers' outputs (written by tools/selftest.sh) with the
analytic positions from tools/make_test_gltf.py.  Prints one line per check
with the max abs error and exits 1 if any check fails.

usage: python tools/check_selftest.py OUTDIR
"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import make_test_gltf as ref  # noqa: E402

# float32 storage in the files bounds what any reader can reproduce (~1e-7
# here); Blender also lerps quaternions component-wise between keys, which is
# ~1e-6 off slerp at sub-frames for this animation.
TOL_KEY = 2e-6
TOL_SUBFRAME = 2e-5

failures = []


def report(label, err, tol, extra=""):
    ok = err <= tol
    print("%-4s %-52s max_err=%.3e (tol %.0e)%s" % ("ok" if ok else "FAIL", label, err, tol, extra))
    if not ok:
        failures.append(label)


def load(out, name):
    with open(os.path.join(out, name)) as f:
        return json.load(f)


def check_three(out, name, split=False, rings=None):
    r = load(out, name)
    saved = ref.RING_Y
    if rings:
        ref.set_rings(rings)
    meshes = sorted(r["meshes"], key=lambda m: m["gltf_primitive"] or 0)
    # three splits a multi-primitive mesh into one SkinnedMesh per primitive;
    # concatenating them in primitive order gives the glTF vertex order.
    worst = 0.0
    for k, frame in enumerate(meshes[0]["frames"]):
        t = frame["time"]
        got = np.concatenate([np.array(m["frames"][k]["positions"]).reshape(-1, 3) for m in meshes])
        worst = max(worst, float(np.abs(got - ref.expected_bar(t, split=split)).max()))
    interp = sorted({tr["interpolation"] for tr in r["tracks"]})
    report("three  %s (%d mesh, %d times)" % (name, len(meshes), len(meshes[0]["frames"])), worst, TOL_KEY,
           "  interp=%s eval=%dms" % (",".join(interp), r["eval_ms"]))
    ref.RING_Y = saved


def check_blender(out, name, split=False, tol=TOL_KEY):
    r = load(out, name)
    (m,) = r["meshes"]
    worst = 0.0
    for fr in m["frames"]:
        got = np.array(fr["positions"]).reshape(-1, 3)
        worst = max(worst, float(np.abs(got - ref.expected_bar(fr["time_seconds"], split=split)).max()))
    mp = r["frame_time_mapping"]
    extra = "  verts=%d keys=%d armature_bones=%d rest_err=%s frame=%.4g*t%+g" % (
        m["vertex_count"], m["shape_key_count"], r["armatures"][0]["bone_count"],
        m["rest_check_max_error"], mp["frames_per_second"], mp["frame_offset"])
    report("blender %s (%d frames)" % (name, len(m["frames"])), worst, tol, extra)
    if m["rest_check_max_error"] is None or m["rest_check_max_error"] > 1e-7:
        report("blender %s vertex map vs rest" % name, float("inf"), 0.0)


def check_pc2(out, name):
    r = load(out, name)
    worst = 0.0
    for fr in r["frames"]:
        s = fr["cache_sample"]
        s0 = int(np.floor(s))
        s1 = min(s0 + 1, ref.PC2_SAMPLES - 1)
        a = s - s0
        want = (1 - a) * ref.expected_pc2(s0) + a * ref.expected_pc2(s1)  # linear between samples
        worst = max(worst, float(np.abs(np.array(fr["positions"]).reshape(-1, 3) - want).max()))
    report("blender %s (%d frames)" % (name, len(r["frames"])), worst, TOL_KEY,
           "  samples=%s" % [fr["cache_sample"] for fr in r["frames"]])


def main():
    out = sys.argv[1]
    check_three(out, "three_bar.json")
    check_three(out, "three_split.json", split=True)
    check_three(out, "three_ext.json")
    if os.path.exists(os.path.join(out, "three_big.json")):
        check_three(out, "three_big.json", rings=int(os.environ.get("BIG_RINGS", "3300")))
    check_blender(out, "blender_bar.json")
    check_blender(out, "blender_split.json", split=True)
    check_blender(out, "blender_bar_fps24.json", tol=TOL_SUBFRAME)
    check_pc2(out, "blender_pc2.json")
    if failures:
        print("selftest FAILED: %s" % ", ".join(failures))
        sys.exit(1)
    print("selftest: all reader checks passed")


if __name__ == "__main__":
    main()
