"""Reads an Alembic archive back with the Alembic library itself (PyPI `alembic3d`, PyAlembic; our
writer never reads), for the tests that run without Blender.

usage (the project venv's python: .venv/bin/python):
  read.py FILE.abc [--pc2 REF.pc2 [--mesh NAME]] [--obj GARMENT.obj]
Prints JSON {meshes: [{path, samples, time_per_sample, start_time, faces, uv_scope, user:
{key: value}, self_bounds_ok}], pc2: {frames, points, max_abs}, obj_uvs: {...}} — with --pc2, every sample of
the PolyMesh NAME (or its Xform NAME; default the first) against the PC2's frames (same vertex order), the largest coordinate difference.
With --obj, that PolyMesh's UVs (the indexed `uv` param, expanded per face corner) against the
OBJ's own (parsed here: each corner's vertex and `vt`): `corners` read, `unmatched` corners whose
(vertex, UV) pair the OBJ lacks, `uncovered` OBJ pairs the file lacks, `max_uv_diff`.
"""

import argparse
import json
import struct
import sys

import numpy as np
from alembic3d import Abc, AbcGeom

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))
from obj_uv import compare_uvs, obj_pairs  # noqa: E402


def at(schema, s):
    # By the sample's time: the binding takes a plain int for a time in seconds, not an index.
    return schema.getValue(Abc.ISampleSelector(schema.getTimeSampling().getSampleTime(s)))


def walk(obj, out):
    for i in range(obj.getNumChildren()):
        child = obj.getChild(i)
        if AbcGeom.IPolyMesh.matches(child.getHeader()):
            out.append(child)
        walk(child, out)


def user_properties(obj):
    parent = obj.getParent()
    if not AbcGeom.IXform.matches(parent.getHeader()):
        return {}
    props = AbcGeom.IXform(parent, Abc.WrapExistingFlag.kWrapExisting).getSchema().getUserProperties()
    if not props.valid():
        return {}
    return {props.getPropertyHeader(i).getName():
            Abc.IStringProperty(props, props.getPropertyHeader(i).getName()).getValue()
            for i in range(props.getNumProperties())}


def read_pc2(path):
    with open(path, "rb") as fh:
        data = fh.read()
    # Header: 'POINTCACHE2\0', version, point count, start frame, sample rate, sample count.
    points, _start, _rate, samples = struct.unpack_from("<iffi", data, 16)
    frames = np.frombuffer(data, dtype="<f4", count=samples * points * 3, offset=32)
    return frames.reshape(samples, points, 3)


def main(argv):
    ap = argparse.ArgumentParser()
    ap.add_argument("file")
    ap.add_argument("--pc2")
    ap.add_argument("--mesh")
    ap.add_argument("--obj")
    a = ap.parse_args(argv)
    archive = Abc.IArchive(a.file)
    found = []
    walk(archive.getTop(), found)
    out = {"meshes": []}
    for obj in found:
        schema = AbcGeom.IPolyMesh(obj, Abc.WrapExistingFlag.kWrapExisting).getSchema()
        ts = schema.getTimeSampling()
        first = at(schema, 0)
        bounds_ok = True
        for s in range(schema.getNumSamples()):
            v = at(schema, s)
            p = np.array([[q[0], q[1], q[2]] for q in v.getPositions()])
            b = v.getSelfBounds()
            lo, hi = np.array([b.min()[i] for i in range(3)]), np.array([b.max()[i] for i in range(3)])
            bounds_ok &= bool(np.all(p >= lo - 1e-6) and np.all(p <= hi + 1e-6))
        uv = schema.getUVsParam()
        out["meshes"].append({
            "path": obj.getFullName(),
            "samples": schema.getNumSamples(),
            "time_per_sample": ts.getTimeSamplingType().getTimePerCycle(),
            "start_time": ts.getSampleTime(0),
            "faces": len(first.getFaceCounts()),
            "uv_scope": str(uv.getScope()) if uv.valid() else None,
            "user": user_properties(obj),
            "self_bounds_ok": bounds_ok,
        })
    if a.pc2:
        ref = read_pc2(a.pc2)
        named = [o for o in found if a.mesh in (None, o.getName(), o.getParent().getName())]
        obj = named[0]
        schema = AbcGeom.IPolyMesh(obj, Abc.WrapExistingFlag.kWrapExisting).getSchema()
        worst = 0.0
        for s in range(min(schema.getNumSamples(), len(ref))):
            pos = at(schema, s).getPositions()
            p = np.array([[q[0], q[1], q[2]] for q in pos])
            worst = max(worst, float(np.abs(p - ref[s]).max()))
        out["pc2"] = {"frames": int(ref.shape[0]), "points": int(ref.shape[1]), "max_abs": worst}
    if a.obj:
        named = [o for o in found if a.mesh in (None, o.getName(), o.getParent().getName())]
        schema = AbcGeom.IPolyMesh(named[0], Abc.WrapExistingFlag.kWrapExisting).getSchema()
        faces = list(at(schema, 0).getFaceIndices())
        param = schema.getUVsParam()
        if not param.valid():
            out["obj_uvs"] = None
        else:
            sample = param.getIndexedValue(Abc.ISampleSelector(schema.getTimeSampling().getSampleTime(0)))
            vals, idx = sample.getVals(), sample.getIndices()
            corners = [(faces[i], (vals[idx[i]][0], vals[idx[i]][1])) for i in range(len(faces))]
            out["obj_uvs"] = compare_uvs(corners, obj_pairs(a.obj))
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
