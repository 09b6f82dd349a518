#!/usr/bin/env python3
"""Seed corpora for the fuzz targets, built from samples/ (and the analytic test files of
tools/make_test_gltf.py), small enough that the fuzzer mutates them quickly.

usage: .venv/bin/python fuzz/make_seeds.py   (from the repository root; writes fuzz/corpus/TARGET/)
"""
import os
import re
import struct
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SAMPLES = os.path.join(ROOT, "samples")
CORPUS = os.path.join(ROOT, "fuzz", "corpus")


def put(target, name, data):
    d = os.path.join(CORPUS, target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(data)


def read(*parts):
    with open(os.path.join(*parts), "rb") as f:
        return f.read()


def obj_head(text, vertices):
    """The first `vertices` vertices of an OBJ with the faces among them (and their uvs)."""
    out, seen = [], {}
    for line in text.splitlines():
        word = line.split(" ", 1)[0]
        if word in ("v", "vt", "vn"):
            seen[word] = seen.get(word, 0) + 1
            if seen[word] <= vertices:
                out.append(line)
        elif word == "f":
            corners = [c.split("/") for c in line.split()[1:]]
            if all(0 < int(i) <= vertices for c in corners for i in c if i):
                out.append(line)
        else:
            out.append(line)
    return "\n".join(out) + "\n"


def bvh_head(text, frames):
    """The hierarchy and the first `frames` frames of a BVH."""
    head, motion = text.split("MOTION", 1)
    lines = motion.strip().splitlines()
    body = [l for l in lines[2:] if l.strip()][:frames]
    return f"{head}MOTION\nFrames: {len(body)}\n{lines[1]}\n" + "\n".join(body) + "\n"


def vertices_of(obj_text, count):
    pts = []
    for line in obj_text.splitlines():
        if line.startswith("v "):
            pts.append([float(x) for x in line.split()[1:4]])
            if len(pts) == count:
                break
    return pts


def pc2(frames, fps=30.0):
    points = len(frames[0])
    data = b"POINTCACHE2\0" + struct.pack("<iiffi", 1, points, 0.0, 1.0, len(frames))
    for f in frames:
        data += b"".join(struct.pack("<fff", *p) for p in f)
    return data


def mdd(frames, fps=30.0):
    data = struct.pack(">ii", len(frames), len(frames[0]))
    data += b"".join(struct.pack(">f", i / fps) for i in range(len(frames)))
    for f in frames:
        data += b"".join(struct.pack(">fff", *p) for p in f)
    return data


def main():
    garments = os.path.join(SAMPLES, "garments")
    for name in sorted(os.listdir(garments)):
        if name.endswith(".obj"):
            text = read(garments, name).decode("utf-8", "replace")
            put("obj", name.replace(".obj", "_head.obj"), obj_head(text, 60).encode())
    put("obj", "top.obj", read(garments, "top.obj"))

    motions = os.path.join(SAMPLES, "motions")
    for name in sorted(os.listdir(motions)):
        if name.endswith(".bvh"):
            text = read(motions, name).decode()
            put("bvh", name.replace(".bvh", "_3frames.bvh"), bvh_head(text, 3).encode())

    skirt = read(garments, "skirt.obj").decode()
    rest = vertices_of(skirt, 64)
    frames = [[[x, y + 0.01 * f, z] for x, y, z in rest] for f in range(3)]
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([sys.executable, os.path.join(ROOT, "tools", "make_test_gltf.py"), tmp],
                       check=True, stdout=subprocess.DEVNULL)
        bar = {n: read(tmp, n) for n in ("bar.glb", "bar_split.glb", "bar_bad.glb", "cloth.pc2")}
        ext = read(tmp, "bar_ext.gltf")
    caches = {"skirt64.pc2": pc2(frames), "skirt64.mdd": mdd(frames), "cloth.pc2": bar["cloth.pc2"]}
    gltfs = {n: bar[n] for n in ("bar.glb", "bar_split.glb", "bar_bad.glb")}
    gltfs["bar_ext.gltf"] = ext
    gltfs["body.glb"] = read(SAMPLES, "body.glb")
    for name, data in caches.items():
        put("point_cache", name, data)
        put("validate", name, data)
    for name, data in gltfs.items():
        put("gltf_body", name, data)
        put("validate", name, data)
    for target in sorted(os.listdir(CORPUS)):
        files = os.listdir(os.path.join(CORPUS, target))
        size = sum(os.path.getsize(os.path.join(CORPUS, target, f)) for f in files)
        print(f"fuzz/corpus/{target}: {len(files)} seeds, {size} bytes")


if __name__ == "__main__":
    main()
