"""Independent checks of garmentbake's USD files, done by usd-core itself (our writer never evaluates).

usage (the project venv's python: .venv/bin/python):
  check.py validate FILE
      every registered UsdValidation validator on the stage; prints JSON
      {validators, errors: [...], warnings: [...]} and exits 1 when there is an error.
  check.py info FILE
      stage metadata, prims with their types and applied schemas, the `clip` variant set, skinned
      meshes (influences, blend shapes, sparse indices), animations (time samples, channels).
  check.py replay FILE --mesh NAME [--clip VARIANT] [--method query|bake] [--stride K]
                 --reference REF.f32
      positions of the skinned mesh NAME (a prim name under the default prim) at every time sample
      of the bound SkelAnimation, computed by UsdSkel -- the code path USD viewers use -- and
      compared with REF.f32 (raw little-endian float32, frames x points x 3; with --stride K it
      holds every K-th frame). Prints JSON {frames, compared_frames, points, max_mm, per_frame_max_mm}.
        query: UsdSkel.Cache -> SkinningQuery, BlendShapeQuery (blend shapes applied to the rest
               points, then ComputeSkinnedPoints with the skeleton's skinning transforms).
        bake:  UsdSkel.BakeSkinning on an in-memory copy, then reads the baked `points` samples.
  check.py points FILE [--mesh NAME] --reference REF.f32
      the time-sampled `points` of the default prim (a Mesh), or of the Mesh NAME under it,
      against REF.f32; also checks that every `extent` sample bounds its points. Prints JSON
      {frames, points, max_abs, extent_ok}.
  check.py uvs FILE [--mesh NAME] --obj GARMENT.obj
      the `primvars:st` of that Mesh as UsdGeom.Primvar computes it (ComputeFlattened, per face
      corner with faceVertexIndices) against the OBJ's own (vertex, vt) corner pairs, parsed here.
      Prints JSON {interpolation, indexed, corners, unmatched, uncovered, obj_pairs, max_uv_diff}.
"""

import argparse
import json
import sys

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, UsdValidation

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))
from obj_uv import compare_uvs, obj_pairs  # noqa: E402


def validate(path):
    stage = Usd.Stage.Open(path)
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    context = UsdValidation.ValidationContext(validators)
    errors, warnings = [], []
    for e in context.Validate(stage):
        if e.HasNoError():
            continue
        entry = {"name": str(e.GetName()), "message": e.GetMessage(),
                 "validator": e.GetValidator().GetMetadata().name if e.GetValidator() else None}
        kind = e.GetType()
        if kind == UsdValidation.ValidationErrorType.Error:
            errors.append(entry)
        elif kind == UsdValidation.ValidationErrorType.Warn:
            warnings.append(entry)
    print(json.dumps({"file": path, "validators": len(validators),
                      "errors": errors, "warnings": warnings}, indent=1))
    return 1 if errors else 0


def info(path):
    stage = Usd.Stage.Open(path)
    layer = stage.GetRootLayer()
    out = {
        "upAxis": UsdGeom.GetStageUpAxis(stage),
        "metersPerUnit": UsdGeom.GetStageMetersPerUnit(stage),
        "timeCodesPerSecond": stage.GetTimeCodesPerSecond(),
        "framesPerSecond": stage.GetFramesPerSecond(),
        "startTimeCode": stage.GetStartTimeCode(),
        "endTimeCode": stage.GetEndTimeCode(),
        "hasAuthoredTimeCodeRange": stage.HasAuthoredTimeCodeRange(),
        "defaultPrim": stage.GetDefaultPrim().GetName() if stage.GetDefaultPrim() else None,
        "customLayerData": dict(layer.customLayerData),
        "prims": {},
        "variants": {},
        "meshes": {},
        "animations": {},
    }
    for prim in stage.Traverse():
        out["prims"][str(prim.GetPath())] = {
            "type": str(prim.GetTypeName()),
            "schemas": list(prim.GetAppliedSchemas()),
        }
        vsets = prim.GetVariantSets()
        for name in vsets.GetNames():
            vs = vsets.GetVariantSet(name)
            out["variants"][str(prim.GetPath())] = {
                "set": name, "names": vs.GetVariantNames(), "selection": vs.GetVariantSelection()}
        if prim.IsA(UsdGeom.Mesh):
            mesh = UsdGeom.Mesh(prim)
            binding = UsdSkel.BindingAPI(prim)
            m = {
                "points": len(mesh.GetPointsAttr().Get(Usd.TimeCode.EarliestTime()) or []),
                "points_time_samples": mesh.GetPointsAttr().GetNumTimeSamples(),
                "extent_time_samples": mesh.GetExtentAttr().GetNumTimeSamples(),
                "has_extent": mesh.GetExtentAttr().HasAuthoredValue(),
                "st": UsdGeom.PrimvarsAPI(prim).HasPrimvar("st"),
                "subdivisionScheme": mesh.GetSubdivisionSchemeAttr().Get(),
                "skinned": prim.HasAPI(UsdSkel.BindingAPI),
            }
            if m["skinned"]:
                ji = binding.GetJointIndicesPrimvar()
                m["influences"] = ji.GetElementSize()
                m["interpolation"] = ji.GetInterpolation()
                m["geomBindTransform"] = binding.GetGeomBindTransformAttr().HasAuthoredValue()
                m["skeleton"] = [str(t) for t in binding.GetSkeletonRel().GetTargets()]
                shapes = binding.GetBlendShapesAttr().Get() or []
                m["blendShapes"] = list(shapes)
                m["blendShapeTargets"] = {}
                for t in binding.GetBlendShapeTargetsRel().GetTargets():
                    bs = UsdSkel.BlendShape(stage.GetPrimAtPath(t))
                    idx = bs.GetPointIndicesAttr().Get()
                    m["blendShapeTargets"][str(t)] = {
                        "offsets": len(bs.GetOffsetsAttr().Get()),
                        "pointIndices": None if idx is None else len(idx),
                    }
            out["meshes"][str(prim.GetPath())] = m
        if prim.IsA(UsdSkel.Animation):
            anim = UsdSkel.Animation(prim)
            out["animations"][str(prim.GetPath())] = {
                "joints": len(anim.GetJointsAttr().Get()),
                "translation_samples": anim.GetTranslationsAttr().GetNumTimeSamples(),
                "rotation_samples": anim.GetRotationsAttr().GetNumTimeSamples(),
                "scales": anim.GetScalesAttr().HasAuthoredValue(),
                "blendShapes": list(anim.GetBlendShapesAttr().Get() or []),
                "weight_samples": anim.GetBlendShapeWeightsAttr().GetNumTimeSamples(),
            }
        if prim.IsA(UsdSkel.Skeleton):
            skel = UsdSkel.Skeleton(prim)
            out["skeleton"] = {
                "path": str(prim.GetPath()),
                "joints": list(skel.GetJointsAttr().Get()),
                "bindTransforms": len(skel.GetBindTransformsAttr().Get()),
                "restTransforms": len(skel.GetRestTransformsAttr().Get()),
                "animationSource": [str(t) for t in
                                    UsdSkel.BindingAPI(prim).GetAnimationSourceRel().GetTargets()],
            }
    print(json.dumps(out, indent=1, default=str))
    return 0


def _reference(path, points):
    ref = np.fromfile(path, dtype="<f4")
    return ref.reshape(-1, points, 3)


def _select_clip(stage, clip):
    if clip is None:
        return
    for prim in stage.Traverse():
        vs = prim.GetVariantSets()
        if "clip" in vs.GetNames():
            if clip not in vs.GetVariantSet("clip").GetVariantNames():
                raise SystemExit("no clip variant %r" % clip)
            vs.GetVariantSet("clip").SetVariantSelection(clip)
            return
    raise SystemExit("no `clip` variant set")


def _skinned_by_query(stage, mesh_prim):
    cache = UsdSkel.Cache()
    root = UsdSkel.Root.Find(mesh_prim)
    cache.Populate(root, Usd.TraverseInstanceProxies())
    skinning = cache.GetSkinningQuery(mesh_prim)
    skel_query = cache.GetSkelQuery(UsdSkel.BindingAPI(mesh_prim).GetInheritedSkeleton())
    anim = skel_query.GetAnimQuery()
    times = anim.GetJointTransformTimeSamples()
    rest = UsdGeom.Mesh(mesh_prim).GetPointsAttr().Get()
    shapes = None
    if skinning.HasBlendShapes():
        shapes = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(mesh_prim))
        offsets = shapes.ComputeSubShapePointOffsets()
        indices = shapes.ComputeBlendShapePointIndices()
        mapper = skinning.GetBlendShapeMapper()
    frames = []
    for t in times:
        t = Usd.TimeCode(t)
        points = type(rest)(rest)
        if shapes is not None:
            # Animation channel order -> the mesh's skel:blendShapes order, then per sub-shape.
            weights = anim.ComputeBlendShapeWeights(t)
            weights = mapper.RemapFloat(weights) if not mapper.IsIdentity() else weights
            sub_weights, shape_indices, sub_indices = shapes.ComputeSubShapeWeights(weights)
            shapes.ComputeDeformedPoints(sub_weights, shape_indices, sub_indices,
                                         indices, offsets, points)
        xforms = skel_query.ComputeSkinningTransforms(t)
        skinning.ComputeSkinnedPoints(xforms, points, t)
        frames.append(np.asarray(points, dtype=np.float64))
    return times, np.stack(frames)


def _skinned_by_bake(stage, mesh_path):
    # BakeSkinning rewrites the stage it is given: work on an in-memory copy of the layer.
    layer = Sdf.Layer.CreateAnonymous(".usda")
    layer.TransferContent(stage.GetRootLayer())
    copy = Usd.Stage.Open(layer)
    for prim in stage.Traverse():
        vs = prim.GetVariantSets()
        if "clip" in vs.GetNames():
            copy.GetPrimAtPath(prim.GetPath()).GetVariantSets().GetVariantSet("clip") \
                .SetVariantSelection(vs.GetVariantSet("clip").GetVariantSelection())
    root = UsdSkel.Root.Find(copy.GetPrimAtPath(mesh_path))
    if not UsdSkel.BakeSkinning(root, Gf.Interval(copy.GetStartTimeCode(), copy.GetEndTimeCode())):
        raise SystemExit("UsdSkel.BakeSkinning failed")
    attr = UsdGeom.Mesh(copy.GetPrimAtPath(mesh_path)).GetPointsAttr()
    times = attr.GetTimeSamples()
    return times, np.stack([np.asarray(attr.Get(t), dtype=np.float64) for t in times])


def replay(path, mesh, clip, method, reference, stride):
    stage = Usd.Stage.Open(path)
    _select_clip(stage, clip)
    mesh_path = stage.GetDefaultPrim().GetPath().AppendChild(mesh)
    mesh_prim = stage.GetPrimAtPath(mesh_path)
    if not mesh_prim:
        raise SystemExit("no mesh %s" % mesh_path)
    if method == "bake":
        times, frames = _skinned_by_bake(stage, mesh_path)
    else:
        times, frames = _skinned_by_query(stage, mesh_prim)
    ref = _reference(reference, frames.shape[1])
    frames = frames[::stride]
    count = min(len(ref), len(frames))
    err = np.linalg.norm(frames[:count] - ref[:count], axis=2).max(axis=1) * 1e3
    print(json.dumps({"file": path, "method": method, "frames": len(times),
                      "compared_frames": count, "reference_frames": len(ref),
                      "points": frames.shape[1],
                      "first_time": times[0], "last_time": times[-1],
                      "max_mm": float(err.max()), "per_frame_max_mm": [float(e) for e in err]}))
    return 0


def _mesh_prim(path, mesh_name):
    """PATH's stage and the mesh prim MESH_NAME under its default prim (or the default prim
    itself); the caller keeps the stage, or the prim dies with it."""
    stage = Usd.Stage.Open(path)
    prim = stage.GetDefaultPrim()
    if mesh_name:
        prim = stage.GetPrimAtPath(prim.GetPath().AppendChild(mesh_name))
    if not prim or not prim.IsA(UsdGeom.Mesh):
        raise SystemExit("no mesh %s in %s" % (mesh_name or "as the default prim", path))
    return stage, prim


def points(path, mesh_name, reference):
    stage, prim = _mesh_prim(path, mesh_name)
    mesh = UsdGeom.Mesh(prim)
    attr = mesh.GetPointsAttr()
    times = attr.GetTimeSamples()
    frames = np.stack([np.asarray(attr.Get(t), dtype=np.float32) for t in times])
    ref = _reference(reference, frames.shape[1])
    extent_ok = True
    for t, f in zip(times, frames):
        lo, hi = np.asarray(mesh.GetExtentAttr().Get(t), dtype=np.float32)
        extent_ok &= bool((f.min(0) == lo).all() and (f.max(0) == hi).all())
    same = len(ref) == len(frames)
    print(json.dumps({"file": path, "frames": len(frames), "reference_frames": len(ref),
                      "points": frames.shape[1], "times": [times[0], times[-1]],
                      "max_abs": float(np.abs(frames - ref).max()) if same else None,
                      "extent_ok": extent_ok}))
    return 0


def uvs(path, mesh_name, obj):
    stage, prim = _mesh_prim(path, mesh_name)
    st = UsdGeom.PrimvarsAPI(prim).GetPrimvar("st")
    if not st:
        print(json.dumps({"file": path, "st": None}))
        return 0
    faces = list(UsdGeom.Mesh(prim).GetFaceVertexIndicesAttr().Get())
    flat = st.ComputeFlattened()
    interpolation = st.GetInterpolation()
    if interpolation == UsdGeom.Tokens.faceVarying:
        corners = [(faces[i], (flat[i][0], flat[i][1])) for i in range(len(faces))]
    else:
        corners = [(v, (flat[v][0], flat[v][1])) for v in faces]
    print(json.dumps({"file": path, "interpolation": str(interpolation), "indexed": st.IsIndexed(),
                      **compare_uvs(corners, obj_pairs(obj))}))
    return 0


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    sub.add_parser("validate").add_argument("file")
    sub.add_parser("info").add_argument("file")
    r = sub.add_parser("replay")
    r.add_argument("file")
    r.add_argument("--mesh", required=True)
    r.add_argument("--clip")
    r.add_argument("--method", choices=["query", "bake"], default="query")
    r.add_argument("--reference", required=True)
    r.add_argument("--stride", type=int, default=1)
    p = sub.add_parser("points")
    p.add_argument("file")
    p.add_argument("--mesh")
    p.add_argument("--reference", required=True)
    u = sub.add_parser("uvs")
    u.add_argument("file")
    u.add_argument("--mesh")
    u.add_argument("--obj", required=True)
    a = ap.parse_args()
    if a.cmd == "validate":
        return validate(a.file)
    if a.cmd == "info":
        return info(a.file)
    if a.cmd == "replay":
        return replay(a.file, a.mesh, a.clip, a.method, a.reference, a.stride)
    if a.cmd == "uvs":
        return uvs(a.file, a.mesh, a.obj)
    return points(a.file, a.mesh, a.reference)


if __name__ == "__main__":
    sys.exit(main())
