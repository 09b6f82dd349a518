"""Reads the meshes of a USD stage as plain data for garmentbake (metres, Y-up, world space)."""
from pxr import Gf, Usd, UsdGeom


def _to_y_up_metres(stage):
    """The matrix that takes the stage's units and up axis to metres, Y-up."""
    scale = UsdGeom.GetStageMetersPerUnit(stage)
    m = Gf.Matrix4d().SetScale(Gf.Vec3d(scale, scale, scale))
    if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z:
        # Z-up → Y-up: a rotation of -90° about X (y' = z, z' = -y).
        m = m * Gf.Matrix4d().SetRotate(Gf.Rotation(Gf.Vec3d(1, 0, 0), -90))
    return m


def read_meshes(path):
    stage = Usd.Stage.Open(path)
    if stage is None:
        raise RuntimeError(f"cannot open USD stage {path}")
    fix = _to_y_up_metres(stage)
    cache = UsdGeom.XformCache(Usd.TimeCode.Default())
    meshes = []
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.Mesh):
            continue
        mesh = UsdGeom.Mesh(prim)
        world = cache.GetLocalToWorldTransform(prim) * fix
        points = [world.Transform(Gf.Vec3d(p)) for p in (mesh.GetPointsAttr().Get() or [])]
        counts = list(mesh.GetFaceVertexCountsAttr().Get() or [])
        indices = list(mesh.GetFaceVertexIndicesAttr().Get() or [])
        # Faces wind counter-clockwise in our meshes: flip left-handed ones and mirrored transforms.
        flip = (mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded) != (world.GetDeterminant() < 0)
        if flip:
            start = 0
            for n in counts:
                indices[start:start + n] = [indices[start]] + indices[start + 1:start + n][::-1]
                start += n
        meshes.append({
            "path": str(prim.GetPath()),
            "points": [float(c) for p in points for c in p],
            "face_counts": [int(n) for n in counts],
            "face_indices": [int(i) for i in indices],
        })
    return meshes
