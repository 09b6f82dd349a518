"""Authors UsdSkel assets and time-sampled point caches with Pixar's usd-core.

Embedded in the garmentbake binary (python_bridge, `include_str!`). The Rust side (exporters/src/usd.rs)
has already done every decision and all the arithmetic: prim names are valid and unique, matrices are
inverted, sparse blend-shape indices chosen, times computed. This module only maps that plain data onto
USD schemas. Arrays arrive as flat memoryviews cast to 'f' / 'i' / 'd' and go into Vt arrays with
`FromBuffer` (one copy, no per-element Python), which is what keeps a 10k x 500 cache under a second.
"""

import os
import re
import shutil
import tempfile

from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdSkel, UsdUtils, Vt


def _chunk(mv, i, n):
    """Element block i of size n of a flat memoryview (zero-copy slice)."""
    return mv[i * n:(i + 1) * n]


def _stage(spec):
    """In-memory stage with the metadata every output carries."""
    stage = Usd.Stage.CreateInMemory()
    # Metres, Y-up unless a point cache was written in another space (--units, --up).
    up = UsdGeom.Tokens.z if spec.get("up_axis") == "Z" else UsdGeom.Tokens.y
    stage.SetMetadata("upAxis", up)
    stage.SetMetadata("metersPerUnit", spec.get("meters_per_unit", 1.0))
    stage.SetTimeCodesPerSecond(spec["fps"])
    stage.SetFramesPerSecond(spec["fps"])
    stage.SetStartTimeCode(spec["start"])
    stage.SetEndTimeCode(spec["end"])
    layer = stage.GetRootLayer()
    if spec["provenance"]:
        # A dictionary is written sorted by key: deterministic whatever the insertion order.
        layer.customLayerData = {"garmentbake": dict(spec["provenance"])}
    return stage


def _mesh_topology(mesh, m):
    """faceVertexCounts / faceVertexIndices / st: the parts a skinned mesh and a cache share."""
    indices = Vt.IntArray.FromBuffer(m["face_indices"])
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray(len(indices) // 3, 3))
    mesh.CreateFaceVertexIndicesAttr(indices)
    # Triangles as authored: without this a renderer would Catmull-Clark subdivide the garment.
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    # Garments are open surfaces: both sides must render.
    mesh.CreateDoubleSidedAttr(True)
    if m.get("uv_indices") is not None:
        # A point cache's face-varying UVs: the coordinates, indexed per face corner.
        st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
            "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying)
        st.Set(Vt.Vec2fArray.FromBuffer(m["uvs"]))
        st.SetIndices(Vt.IntArray.FromBuffer(m["uv_indices"]))
    elif m.get("uvs") is not None:
        st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
            "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
        st.Set(Vt.Vec2fArray.FromBuffer(m["uvs"]))
    if m.get("color") is not None:
        mesh.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set(
            Vt.Vec3fArray([Gf.Vec3f(*m["color"])]))


def _export(stage, path):
    """Writes the root layer to `path`; the format follows the extension (.usda, .usdc, .usdz)."""
    try:
        _export_layer(stage.GetRootLayer(), path)
    except Tf.ErrorException as e:
        # Tf reports every error with its C++ function, file and line; the user needs the reasons.
        chunks = re.split(r"\s*Error in ", str(e))
        reasons = [c.split(" : ", 1)[1].strip().strip("'") for c in chunks if " : " in c]
        raise RuntimeError("usd-core: " + "; ".join(reasons or [str(e)])) from None


def _export_layer(layer, path):
    if not path.endswith(".usdz"):
        if not layer.Export(path):
            raise RuntimeError("usd-core could not write " + path)
        return
    # A .usdz is a zip around a .usdc; the inner file is named after the final output so the package
    # does not depend on the temporary name it is written under.
    inner = _inner_name(path)
    tmp = tempfile.mkdtemp(prefix="garmentbake-usdz-")
    try:
        usdc = os.path.join(tmp, inner)
        if not layer.Export(usdc):
            raise RuntimeError("usd-core could not write " + usdc)
        # The zip records the file's modification time: pin it so packages are byte-identical.
        os.utime(usdc, (946684800, 946684800))
        if not UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(usdc), path):
            raise RuntimeError("usd-core could not package " + path)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _inner_name(path):
    """`.skirt.partial.usdz` (our temporary name) -> `skirt.usdc`."""
    base = os.path.basename(path)
    if base.startswith(".") and base.endswith(".partial.usdz"):
        base = base[1:-len(".partial.usdz")] + ".usdz"
    return base[:-len(".usdz")] + ".usdc"


def write_skel(spec, path):
    """A SkelRoot with a Skeleton, skinned meshes with BlendShapes, and one SkelAnimation per clip."""
    stage = _stage(spec)
    root_path = Sdf.Path("/" + spec["root"])
    root = UsdSkel.Root.Define(stage, root_path)
    stage.SetDefaultPrim(root.GetPrim())
    sk = spec["skeleton"]
    skel_path = root_path.AppendChild(sk["prim"])
    skel = UsdSkel.Skeleton.Define(stage, skel_path)
    joints = Vt.TokenArray(sk["joints"])
    skel.CreateJointsAttr(joints)
    skel.CreateJointNamesAttr(Vt.TokenArray(sk["joint_names"]))
    skel.CreateBindTransformsAttr(Vt.Matrix4dArray.FromBuffer(sk["bind"]))
    skel.CreateRestTransformsAttr(Vt.Matrix4dArray.FromBuffer(sk["rest"]))

    for m in spec["meshes"]:
        _skinned_mesh(stage, root_path.AppendChild(m["prim"]), m, skel_path)

    anim_paths = []
    if spec["animations"]:
        scope_path = root_path.AppendChild(spec["animations_scope"])
        UsdGeom.Scope.Define(stage, scope_path)
        for a in spec["animations"]:
            anim_path = scope_path.AppendChild(a["prim"])
            _animation(stage, anim_path, a, joints)
            anim_paths.append(anim_path)

    binding = UsdSkel.BindingAPI.Apply(skel.GetPrim())
    if len(anim_paths) == 1:
        binding.CreateAnimationSourceRel().SetTargets([anim_paths[0]])
    elif anim_paths:
        vset = skel.GetPrim().GetVariantSets().AddVariantSet("clip")
        for a, anim_path in zip(spec["animations"], anim_paths):
            vset.AddVariant(a["prim"])
            vset.SetVariantSelection(a["prim"])
            with vset.GetVariantEditContext():
                binding.CreateAnimationSourceRel().SetTargets([anim_path])
        vset.SetVariantSelection(spec["animations"][0]["prim"])
    _export(stage, path)


def _skinned_mesh(stage, path, m, skel_path):
    mesh = UsdGeom.Mesh.Define(stage, path)
    points = Vt.Vec3fArray.FromBuffer(m["points"])
    mesh.CreatePointsAttr(points)
    mesh.CreateExtentAttr(Vt.Vec3fArray.FromBuffer(m["extent"]))
    if m.get("normals") is not None:
        mesh.CreateNormalsAttr(Vt.Vec3fArray.FromBuffer(m["normals"]))
        mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    _mesh_topology(mesh, m)
    skin, shapes = m.get("skin"), m["blend_shapes"]
    if skin is None and not shapes:
        return  # a static mesh (e.g. a prop): nothing for UsdSkel to deform

    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel_path])
    # Points are authored in skeleton space at bind time: the identity is the truth, written out
    # so no reader has to guess.
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
    if skin is not None:
        k = skin["influences"]
        binding.CreateJointIndicesPrimvar(False, k).Set(Vt.IntArray.FromBuffer(skin["indices"]))
        binding.CreateJointWeightsPrimvar(False, k).Set(Vt.FloatArray.FromBuffer(skin["weights"]))
    if shapes:
        targets = []
        for s in shapes:
            shape = UsdSkel.BlendShape.Define(stage, path.AppendChild(s["prim"]))
            shape.CreateOffsetsAttr(Vt.Vec3fArray.FromBuffer(s["offsets"]))
            if s.get("normal_offsets") is not None:
                shape.CreateNormalOffsetsAttr(Vt.Vec3fArray.FromBuffer(s["normal_offsets"]))
            if s.get("point_indices") is not None:
                shape.CreatePointIndicesAttr(Vt.IntArray.FromBuffer(s["point_indices"]))
            targets.append(shape.GetPath())
        binding.CreateBlendShapesAttr(Vt.TokenArray([s["channel"] for s in shapes]))
        binding.CreateBlendShapeTargetsRel().SetTargets(targets)


def _animation(stage, path, a, joints):
    anim = UsdSkel.Animation.Define(stage, path)
    anim.CreateJointsAttr(joints)
    n = len(joints)
    translations = anim.CreateTranslationsAttr()
    rotations = anim.CreateRotationsAttr()
    # Our rigs never scale joints: one default value instead of a sample per frame.
    anim.CreateScalesAttr(Vt.Vec3hArray(n, Gf.Vec3h(1.0, 1.0, 1.0)))
    channels = a["channels"]
    weights = None
    if channels:
        anim.CreateBlendShapesAttr(Vt.TokenArray(channels))
        weights = anim.CreateBlendShapeWeightsAttr()
    with Sdf.ChangeBlock():
        for f, t in enumerate(a["times"]):
            time = Usd.TimeCode(t)
            translations.Set(Vt.Vec3fArray.FromBuffer(_chunk(a["translations"], f, 3 * n)), time)
            rotations.Set(Vt.QuatfArray.FromBuffer(_chunk(a["rotations"], f, 4 * n)), time)
            if weights is not None:
                weights.Set(Vt.FloatArray.FromBuffer(_chunk(a["weights"], f, len(channels))), time)


def write_point_cache(spec, path):
    """Meshes whose `points` and `extent` are sampled at every frame (the USD form of a PC2): one
    mesh is the root prim, several are children of a root Xform (a garment and its body)."""
    stage = _stage(spec)
    root = Sdf.Path("/" + spec["root"])
    meshes = spec["meshes"]
    if len(meshes) == 1:
        prims = [(root, meshes[0])]
    else:
        UsdGeom.Xform.Define(stage, root)
        prims = [(root.AppendChild(m["name"]), m) for m in meshes]
    for prim_path, m in prims:
        _mesh_cache(stage, prim_path, m, spec["times"])
    stage.SetDefaultPrim(stage.GetPrimAtPath(root))
    _export(stage, path)


def _mesh_cache(stage, prim_path, m, times):
    mesh = UsdGeom.Mesh.Define(stage, prim_path)
    _mesh_topology(mesh, m)
    points = mesh.CreatePointsAttr()
    extent = mesh.CreateExtentAttr()
    n = m["point_count"]
    # Setting values on attributes that already exist: batching the notices is safe and cheaper.
    with Sdf.ChangeBlock():
        for f, t in enumerate(times):
            time = Usd.TimeCode(t)
            points.Set(Vt.Vec3fArray.FromBuffer(_chunk(m["points"], f, 3 * n)), time)
            extent.Set(Vt.Vec3fArray.FromBuffer(_chunk(m["extents"], f, 6)), time)
