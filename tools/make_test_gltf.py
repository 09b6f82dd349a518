#!/usr/bin/env python3
"""Build tiny reference inputs for tools/selftest.sh WITHOUT garmentbake.

Only numpy + json + struct, so the reference files are independent of the
Rust exporter.  Everything here is analytic, so the readers (Khronos
validator, three.js, Blender) can be checked against exact positions.

Outputs (in OUTDIR):
  bar.glb        2-joint bar (5 rings x 4 verts), blended weights, 1 morph
                 target "bulge", animation "Bend": Root translation+rotation,
                 Tip rotation, mesh morph weights; 31 keys at 30 fps, LINEAR.
  bar_split.glb  same, but the mesh is 2 primitives (rings 0-2, rings 2-4),
                 to see how readers split/merge primitives.
  bar_ext.gltf + bar_ext.bin   bar.glb as JSON + external buffer
  bar_bad.glb    INVALID on purpose (skin weights sum to 0.9): the validator
                 must fail on it
  big.glb        (--big-rings N) the bar with N rings, for timing
  cloth.obj      3x3 grid (9 verts, 4 quads), Y-up
  cloth.pc2      5 samples of that grid, Y-up, startFrame 0, sampleRate 1

Also importable: expected_bar(t, split=False) and expected_pc2(sample) give
the analytic world-space positions in glTF / file (Y-up) coordinates.

usage: python tools/make_test_gltf.py OUTDIR [--big-rings N]
"""
import json
import math
import os
import struct
import sys

import numpy as np

FPS = 30
DURATION = 1.0
NKEYS = int(round(DURATION * FPS)) + 1  # 31 keys: t = 0, 1/30, ..., 1
ROOT_REST = np.array([0.3, 0.0, 0.0])  # non-zero so inverse bind matrices are non-trivial
TIP_OFFSET = np.array([0.0, 1.0, 0.0])

# ---------------------------------------------------------------- geometry
RING_Y = [0.0, 0.5, 1.0, 1.5, 2.0]
CORNERS = [(-0.1, -0.1), (0.1, -0.1), (0.1, 0.1), (-0.1, 0.1)]  # (x, z)


def bar_rest():
    """Rest positions, vertex i = 4*ring + corner."""
    p = [(ROOT_REST[0] + cx, y, cz) for y in RING_Y for (cx, cz) in CORNERS]
    return np.array(p, dtype=np.float64)


def bar_weights(p):
    """Blended 2-joint weights: Tip weight ramps 0 -> 1 between y=0.5 and y=1.5."""
    w1 = np.clip((p[:, 1] - 0.5) / 1.0, 0.0, 1.0)
    return np.stack([1.0 - w1, w1], axis=1)


def bar_morph_delta(p):
    """Morph target 'bulge' (relative displacement, as glTF stores it)."""
    n = len(p)
    c = np.arange(n) % 4
    return np.stack([0.1 * p[:, 1], 0.02 * c, np.full(n, 0.05)], axis=1)


def bar_triangles(r0, r1):
    """Side quads between rings r0..r1 (vertex numbering local to ring r0)."""
    tris = []
    for r in range(r1 - r0):
        for c in range(4):
            c1 = (c + 1) % 4
            a, b, cc, d = 4 * r + c, 4 * r + c1, 4 * (r + 1) + c1, 4 * (r + 1) + c
            tris += [a, b, cc, a, cc, d]
    return tris


# ---------------------------------------------------------------- animation (analytic)
def root_translation(t):
    return ROOT_REST + np.array([0.0, 0.0, 0.2 * t])


def root_angle(t):  # about +X
    return 0.5 * t


def tip_angle(t):  # about +Z
    return 0.5 * math.pi * t


def morph_weight(t):
    return t


def quat_axis(axis, ang):
    """glTF quaternion [x, y, z, w]."""
    s = math.sin(ang / 2)
    a = np.asarray(axis, dtype=np.float64)
    return np.array([a[0] * s, a[1] * s, a[2] * s, math.cos(ang / 2)])


def mat_T(v):
    m = np.eye(4)
    m[:3, 3] = v
    return m


def mat_Rx(a):
    c, s = math.cos(a), math.sin(a)
    m = np.eye(4)
    m[1, 1], m[1, 2], m[2, 1], m[2, 2] = c, -s, s, c
    return m


def mat_Rz(a):
    c, s = math.cos(a), math.sin(a)
    m = np.eye(4)
    m[0, 0], m[0, 1], m[1, 0], m[1, 1] = c, -s, s, c
    return m


def joint_worlds(t):
    root = mat_T(root_translation(t)) @ mat_Rx(root_angle(t))
    tip = root @ mat_T(TIP_OFFSET) @ mat_Rz(tip_angle(t))
    return [root, tip]


def inverse_binds():
    return [np.linalg.inv(mat_T(ROOT_REST)), np.linalg.inv(mat_T(ROOT_REST + TIP_OFFSET))]


def expected_bar(t, split=False):
    """Analytic skinned+morphed world positions (glTF Y-up), shape (n, 3).

    Every channel is linear in t (or a constant-rate single-axis rotation,
    for which slerp is exact), so this is exact at ANY t, not only at keys.
    """
    p = bar_rest()
    pm = p + morph_weight(t) * bar_morph_delta(p)
    w = bar_weights(p)
    skin = [J @ B for J, B in zip(joint_worlds(t), inverse_binds())]
    h = np.concatenate([pm, np.ones((len(pm), 1))], axis=1)
    out = sum(w[:, j:j + 1] * (h @ skin[j].T) for j in range(2))[:, :3]
    if split:  # primitive A = rings 0-2 (verts 0..11), B = rings 2-4 (verts 8..19)
        out = np.concatenate([out[4 * r0:4 * (r1 + 1)] for r0, r1 in prim_ring_ranges(True)])
    return out


def prim_ring_ranges(split):
    """(first ring, last ring) per primitive; split shares the middle ring."""
    nr = len(RING_Y) - 1
    return [(0, nr // 2), (nr // 2, nr)] if split else [(0, nr)]


# ---------------------------------------------------------------- glb writer
class GlbBuilder:
    def __init__(self):
        self.bin = bytearray()
        self.views = []
        self.accessors = []

    def add(self, arr, ctype, atype, target=None, minmax=False):
        """Append one accessor with its own (4-byte aligned) bufferView."""
        fmt = {5126: np.float32, 5123: np.uint16, 5121: np.uint8}[ctype]
        a = np.ascontiguousarray(arr, dtype=fmt)
        while len(self.bin) % 4:
            self.bin.append(0)
        view = {"buffer": 0, "byteOffset": len(self.bin), "byteLength": a.nbytes}
        if target:
            view["target"] = target
        self.views.append(view)
        self.bin += a.tobytes()
        ncomp = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[atype]
        acc = {"bufferView": len(self.views) - 1, "componentType": ctype,
               "count": int(a.size // ncomp), "type": atype}
        if minmax:  # required for POSITION, morph POSITION and animation input
            flat = a.reshape(-1, ncomp)
            acc["min"] = [float(x) for x in flat.min(axis=0)]
            acc["max"] = [float(x) for x in flat.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def _finish(self, gltf, uri=None):
        while len(self.bin) % 4:
            self.bin.append(0)
        gltf["buffers"] = [{"byteLength": len(self.bin)}]
        if uri:
            gltf["buffers"][0]["uri"] = uri
        gltf["bufferViews"] = self.views
        gltf["accessors"] = self.accessors
        return gltf

    def external(self, gltf, bin_name):
        """(.gltf JSON bytes, .bin bytes) with an external buffer URI."""
        gltf = self._finish(gltf, uri=bin_name)
        return json.dumps(gltf, indent=1).encode(), bytes(self.bin)

    def glb(self, gltf):
        gltf = self._finish(gltf)
        js = json.dumps(gltf, separators=(",", ":")).encode()
        js += b" " * ((4 - len(js) % 4) % 4)
        total = 12 + 8 + len(js) + 8 + len(self.bin)
        return (struct.pack("<III", 0x46546C67, 2, total)
                + struct.pack("<II", len(js), 0x4E4F534A) + js
                + struct.pack("<II", len(self.bin), 0x004E4942) + bytes(self.bin))


def build_bar(split=False, external=None, weight_scale=1.0):
    """GLB bytes; with external="name.bin": (gltf_json_bytes, bin_bytes).

    weight_scale != 1 makes an INVALID file (negative control for the validator).
    """
    g = GlbBuilder()
    p = bar_rest()
    w = bar_weights(p)
    d = bar_morph_delta(p)
    ranges = prim_ring_ranges(split)
    prims = []
    for r0, r1 in ranges:
        sl = slice(4 * r0, 4 * (r1 + 1))
        n = sl.stop - sl.start
        weights = np.zeros((n, 4))
        weights[:, :2] = w[sl] * weight_scale
        # joint slot 1 = Tip; a slot with zero weight must hold joint 0
        # (validator warning ACCESSOR_JOINTS_USED_ZERO_WEIGHT otherwise)
        joints = np.zeros((n, 4), np.uint8)
        joints[:, 1] = np.where(weights[:, 1] > 0, 1, 0)
        prims.append({
            "attributes": {
                "POSITION": g.add(p[sl], 5126, "VEC3", 34962, minmax=True),
                "JOINTS_0": g.add(joints, 5121, "VEC4", 34962),
                "WEIGHTS_0": g.add(weights, 5126, "VEC4", 34962),
            },
            "indices": g.add(bar_triangles(r0, r1), 5123, "SCALAR", 34963),
            "targets": [{"POSITION": g.add(d[sl], 5126, "VEC3", 34962, minmax=True)}],
            "mode": 4,
        })
    # inverse bind matrices, column-major as glTF wants
    ibm = g.add(np.stack([m.T.reshape(16) for m in inverse_binds()]), 5126, "MAT4")

    times = np.arange(NKEYS) / FPS
    t_in = g.add(times, 5126, "SCALAR", minmax=True)
    s_root_t = g.add(np.stack([root_translation(t) for t in times]), 5126, "VEC3")
    s_root_r = g.add(np.stack([quat_axis([1, 0, 0], root_angle(t)) for t in times]), 5126, "VEC4")
    s_tip_r = g.add(np.stack([quat_axis([0, 0, 1], tip_angle(t)) for t in times]), 5126, "VEC4")
    s_w = g.add(np.array([morph_weight(t) for t in times]), 5126, "SCALAR")  # 1 target/key

    gltf = {
        "asset": {"version": "2.0", "generator": "garmentbake tools/make_test_gltf.py"},
        "scene": 0,
        "scenes": [{"name": "Scene", "nodes": [0, 1]}],
        "nodes": [
            # skinned mesh node: no transform (spec ignores it; validator warns otherwise)
            {"name": "Bar", "mesh": 0, "skin": 0},
            {"name": "Root", "translation": ROOT_REST.tolist(), "children": [2]},
            {"name": "Tip", "translation": TIP_OFFSET.tolist()},
        ],
        "meshes": [{"name": "BarMesh", "primitives": prims, "weights": [0.0],
                    "extras": {"targetNames": ["bulge"]}}],
        "skins": [{"name": "Armature", "joints": [1, 2], "skeleton": 1,
                   "inverseBindMatrices": ibm}],
        "animations": [{
            "name": "Bend",
            "samplers": [
                {"input": t_in, "output": s_root_t, "interpolation": "LINEAR"},
                {"input": t_in, "output": s_root_r, "interpolation": "LINEAR"},
                {"input": t_in, "output": s_tip_r, "interpolation": "LINEAR"},
                {"input": t_in, "output": s_w, "interpolation": "LINEAR"},
            ],
            "channels": [
                {"sampler": 0, "target": {"node": 1, "path": "translation"}},
                {"sampler": 1, "target": {"node": 1, "path": "rotation"}},
                {"sampler": 2, "target": {"node": 2, "path": "rotation"}},
                {"sampler": 3, "target": {"node": 0, "path": "weights"}},
            ],
        }],
    }
    return g.external(gltf, external) if external else g.glb(gltf)


# ---------------------------------------------------------------- OBJ + PC2
def cloth_rest():
    """3x3 grid in the XZ plane (Y up), vertex i = 3*row + col."""
    return np.array([(0.5 * c, 0.0, 0.5 * r) for r in range(3) for c in range(3)], dtype=np.float64)


PC2_SAMPLES = 5


def expected_pc2(sample):
    """Cache contents at sample index s (Y-up, file coordinates)."""
    p = cloth_rest()
    k = np.arange(len(p))
    return p + sample * np.stack([np.full(len(p), 0.1), 0.05 * k, np.full(len(p), -0.2)], axis=1)


def write_obj(path):
    p = cloth_rest()
    with open(path, "w") as f:
        f.write("# garmentbake selftest grid, Y-up\no cloth\n")
        for v in p:
            f.write("v %.9g %.9g %.9g\n" % tuple(v))
        for r in range(2):
            for c in range(2):
                a = 3 * r + c + 1  # OBJ is 1-based
                f.write("f %d %d %d %d\n" % (a, a + 3, a + 4, a + 1))


def write_pc2(path, samples, start_frame=0.0, sample_rate=1.0):
    n = len(samples[0])
    with open(path, "wb") as f:
        f.write(b"POINTCACHE2\0")
        f.write(struct.pack("<iiffi", 1, n, start_frame, sample_rate, len(samples)))
        for s in samples:
            f.write(np.asarray(s, dtype="<f4").tobytes())


def set_rings(n):
    """Use n evenly spaced rings over y in [0, 2] (4 verts each) instead of 5."""
    global RING_Y
    RING_Y = list(np.linspace(0.0, 2.0, n))


def main():
    import argparse
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("outdir")
    ap.add_argument("--big-rings", type=int, default=0,
                    help="also write big.glb: the bar with N rings (4*N verts), for timing")
    a = ap.parse_args()
    out = a.outdir
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "bar.glb"), "wb") as f:
        f.write(build_bar(split=False))
    with open(os.path.join(out, "bar_split.glb"), "wb") as f:
        f.write(build_bar(split=True))
    # negative control: weights scaled by 0.9 -> validator must report an error
    with open(os.path.join(out, "bar_bad.glb"), "wb") as f:
        f.write(build_bar(split=False, weight_scale=0.9))
    # .gltf + external .bin: exercises validate.mjs's external-resource loader
    js, bn = build_bar(split=False, external="bar_ext.bin")
    with open(os.path.join(out, "bar_ext.gltf"), "wb") as f:
        f.write(js)
    with open(os.path.join(out, "bar_ext.bin"), "wb") as f:
        f.write(bn)
    write_obj(os.path.join(out, "cloth.obj"))
    write_pc2(os.path.join(out, "cloth.pc2"), [expected_pc2(s) for s in range(PC2_SAMPLES)])
    if a.big_rings:
        set_rings(a.big_rings)
        with open(os.path.join(out, "big.glb"), "wb") as f:
            f.write(build_bar(split=False))
    print("wrote bar.glb bar_split.glb bar_bad.glb bar_ext.gltf+.bin cloth.obj cloth.pc2%s in %s"
          % (" big.glb" if a.big_rings else "", out))


if __name__ == "__main__":
    main()
