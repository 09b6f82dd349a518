"""Plays a USD garment the way USD viewers do, for garmentbake validate's replay against the model:
the mesh's points at every frame of a clip through UsdSkel (BlendShapeQuery: sub-shape weights and
offsets added to the rest points; SkinningQuery: skinned by the Skeleton's skinning transforms), or
its time-sampled `points` when it is not skinned (a point cache). Nothing here is our own evaluator.

replay(path, counts, clip, fps, frames) -> {"mesh", "skinned", "samples", "points": bytes} or
{"error": reason}; frame f is evaluated at time code f * timeCodesPerSecond / fps, or (fps 0: a
rate nobody gave) at the file's own f-th time sample.
"""
import numpy as np
from pxr import Usd, UsdGeom, UsdSkel


def _select_clip(stage, clip):
    """Selects the `clip` variant named after the clip (or the only one); None, or why not."""
    for prim in stage.Traverse():
        sets = prim.GetVariantSets()
        if "clip" not in sets.GetNames():
            continue
        vset = sets.GetVariantSet("clip")
        names = vset.GetVariantNames()
        if clip in names:
            vset.SetVariantSelection(clip)
        elif len(names) == 1:
            vset.SetVariantSelection(names[0])
        else:
            return "no `clip` variant is named %r (the clip); the file has %s" % (clip, list(names))
        return None
    return None


def _point_count(prim):
    # A point cache has time samples only: the earliest stands for them all.
    points = UsdGeom.Mesh(prim).GetPointsAttr().Get(Usd.TimeCode.EarliestTime())
    return len(points or [])


def _mesh(stage, counts):
    """The mesh holding one of `counts` points (the one named `garment` when several do)."""
    found = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh) and _point_count(p) in counts]
    named = [p for p in found if p.GetName() == "garment"]
    return (named or found or [None])[0]


def _times(stage, samples, fps, frames):
    if fps > 0:
        return [f * stage.GetTimeCodesPerSecond() / fps for f in range(frames)]
    return list(samples)[:frames]


def _skinned(stage, prim, fps, frames):
    cache = UsdSkel.Cache()
    root = UsdSkel.Root.Find(prim)
    if not root:
        return "the skinned mesh %s is under no SkelRoot" % prim.GetPath()
    cache.Populate(root, Usd.TraverseInstanceProxies())
    skinning = cache.GetSkinningQuery(prim)
    skel_query = cache.GetSkelQuery(UsdSkel.BindingAPI(prim).GetInheritedSkeleton())
    if not skinning or not skel_query:
        return "UsdSkel cannot skin %s (no valid skinning or skeleton query)" % prim.GetPath()
    anim = skel_query.GetAnimQuery()
    samples = anim.GetJointTransformTimeSamples() if anim else []
    times = _times(stage, samples, fps, frames)
    rest = UsdGeom.Mesh(prim).GetPointsAttr().Get()
    shapes = None
    if skinning.HasBlendShapes():
        shapes = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(prim))
        offsets = shapes.ComputeSubShapePointOffsets()
        indices = shapes.ComputeBlendShapePointIndices()
        mapper = skinning.GetBlendShapeMapper()
    out = []
    for t in times:
        t = Usd.TimeCode(t)
        points = type(rest)(rest)
        if shapes is not None and anim:
            # The animation's channel order -> the mesh's skel:blendShapes order.
            weights = anim.ComputeBlendShapeWeights(t)
            weights = weights if mapper.IsIdentity() else mapper.RemapFloat(weights)
            sub_weights, shape_indices, sub_indices = shapes.ComputeSubShapeWeights(weights)
            shapes.ComputeDeformedPoints(sub_weights, shape_indices, sub_indices,
                                         indices, offsets, points)
        xforms = skel_query.ComputeSkinningTransforms(t)
        if xforms is None or not skinning.ComputeSkinnedPoints(xforms, points, t):
            return "UsdSkel could not skin %s at time %g" % (prim.GetPath(), t.GetValue())
        out.append(np.asarray(points, dtype="<f4"))
    return len(samples), out


def replay(path, counts, clip, fps, frames):
    stage = Usd.Stage.Open(path)
    if stage is None:
        return {"error": "cannot open the USD stage"}
    why = _select_clip(stage, clip)
    if why:
        return {"error": why}
    prim = _mesh(stage, set(counts))
    if prim is None:
        return {"error": "no mesh has the model's %s garment points (a file of another model?)"
                % " or ".join(str(c) for c in sorted(set(counts)))}
    skinned = prim.HasAPI(UsdSkel.BindingAPI) and bool(
        UsdSkel.BindingAPI(prim).GetJointIndicesPrimvar())
    if skinned:
        got = _skinned(stage, prim, fps, frames)
        if isinstance(got, str):
            return {"error": got}
        samples, out = got
    else:
        attr = UsdGeom.Mesh(prim).GetPointsAttr()
        samples = attr.GetTimeSamples()
        times = _times(stage, samples, fps, frames)
        out = [np.asarray(attr.Get(Usd.TimeCode(t)), dtype="<f4") for t in times]
        samples = len(samples)
    if len(out) != frames:
        return {"error": "%s has %d time samples, the reference %d frames"
                % (prim.GetPath(), samples, frames)}
    return {"mesh": str(prim.GetPath()), "skinned": skinned, "samples": samples,
            "points": b"".join(p.tobytes() for p in out)}
