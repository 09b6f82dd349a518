"""Checks a USD file for garmentbake validate: usd-core's own UsdValidation validators, then the
UsdSkel binding rules a skinned garment must keep (joint index range, element size, weight sums,
blend shape / target counts, finite time samples). Returns [(severity, where, message)]."""
import math

from pxr import Usd, UsdGeom, UsdSkel, UsdValidation

WEIGHT_SUM = 1e-4


def _validators(stage, out):
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    context = UsdValidation.ValidationContext(validators)
    for e in context.Validate(stage):
        if e.HasNoError():
            continue
        kind = e.GetType()
        severity = "error" if kind == UsdValidation.ValidationErrorType.Error else (
            "warning" if kind == UsdValidation.ValidationErrorType.Warn else None)
        if severity:
            out.append((severity, str(e.GetName()), e.GetMessage()))


def _numbers(v):
    """Every number inside a sample value (scalars, vectors, quaternions, matrices, arrays)."""
    if isinstance(v, bool) or v is None or isinstance(v, str):
        return
    if isinstance(v, (int, float)):
        yield float(v)
    elif hasattr(v, "GetReal"):
        yield float(v.GetReal())
        yield from _numbers(v.GetImaginary())
    else:
        try:
            for x in v:
                yield from _numbers(x)
        except TypeError:
            return


def _finite_samples(attr, where, out):
    for t in attr.GetTimeSamples():
        if not all(math.isfinite(x) for x in _numbers(attr.Get(t))):
            out.append(("error", where, "%s has a non-finite value at time %g" % (attr.GetName(), t)))
            return


def _skinned_mesh(prim, out):
    where = str(prim.GetPath())
    binding = UsdSkel.BindingAPI(prim)
    skel = binding.GetInheritedSkeleton()
    indices = binding.GetJointIndicesPrimvar()
    weights = binding.GetJointWeightsPrimvar()
    if not indices or not indices.HasValue():
        return
    points = len(UsdGeom.Mesh(prim).GetPointsAttr().Get() or [])
    joints = binding.GetJointsAttr().Get() if binding.GetJointsAttr().HasValue() else None
    if joints is None and skel:
        joints = skel.GetJointsAttr().Get()
    if not skel:
        out.append(("error", where, "skinned (jointIndices) but bound to no Skeleton"))
    count = len(joints or [])
    ji = list(indices.Get() or [])
    jw = list(weights.Get() or []) if weights else []
    size = indices.GetElementSize()
    if size < 1 or len(ji) != points * size:
        out.append(("error", where, "jointIndices: %d values for %d points x elementSize %d" % (len(ji), points, size)))
        return
    if weights and (weights.GetElementSize() != size or len(jw) != len(ji)):
        out.append(("error", where, "jointWeights: %d values, elementSize %d; jointIndices: %d, elementSize %d"
                    % (len(jw), weights.GetElementSize(), len(ji), size)))
        return
    bad = [i for i in ji if i < 0 or i >= count]
    if bad:
        out.append(("error", where, "jointIndices hold %d (and %d more) past the skeleton's %d joints"
                    % (bad[0], len(bad) - 1, count)))
    for v in range(points):
        w = jw[v * size:(v + 1) * size]
        if any(x < 0 for x in w) or abs(sum(w) - 1.0) > WEIGHT_SUM:
            out.append(("error", where, "point %d: jointWeights %s do not sum to 1" % (v, list(w))))
            break
    shapes = binding.GetBlendShapesAttr().Get() if binding.GetBlendShapesAttr().HasValue() else []
    targets = binding.GetBlendShapeTargetsRel().GetTargets()
    if len(shapes or []) != len(targets):
        out.append(("error", where, "%d blendShapes but %d blendShapeTargets" % (len(shapes or []), len(targets))))
    for attr in prim.GetAttributes():
        _finite_samples(attr, where, out)


def validate(path):
    out = []
    try:
        stage = Usd.Stage.Open(path)
    except Exception as e:  # a garbled file raises from the layer parser
        return [("error", "/", "cannot open the USD stage: %s" % str(e).strip().splitlines()[-1])]
    if stage is None:
        return [("error", "/", "cannot open the USD stage")]
    _validators(stage, out)
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Mesh):
            _skinned_mesh(prim, out)
            if not UsdSkel.BindingAPI(prim).GetJointIndicesPrimvar():
                for attr in prim.GetAttributes():
                    _finite_samples(attr, str(prim.GetPath()), out)
        elif prim.IsA(UsdSkel.Animation):
            for attr in prim.GetAttributes():
                _finite_samples(attr, str(prim.GetPath()), out)
    return out
