"""Writes time-sampled point caches as an Alembic archive (Ogawa) with PyPI's `alembic3d` (PyAlembic).

Embedded in the garmentbake binary (python_bridge, `include_str!`). The Rust side
(exporters/src/abc.rs) has done every decision: names are unique, faces already in Alembic's
clockwise order, UVs per point. This module only maps the plain buffers onto AbcGeom schemas:
per mesh an `Xform` holding a `PolyMesh` (the layout Maya, Houdini, Blender and Unreal write and
read), topology and UVs in the first sample, positions and bounds in every sample, on one uniform
time sampling at the cache's rate. Alembic has no field for units or up axis (by convention Y-up);
the Xform's user properties say them (`units`, `upAxis`).
"""

import imath
from alembic3d import Abc, AbcCoreAbstract, AbcGeom


def _v3(mv):
    """Flat 'f' memoryview -> V3fArray in one copy (the buffer seen as n x 3)."""
    return imath.V3fArrayFromBuffer(mv.cast("B").cast("f", (len(mv) // 3, 3)))


def _bounds(mv):
    b = mv.tolist()
    return imath.Box3d(imath.V3d(*b[0:3]), imath.V3d(*b[3:6]))


def write_point_caches(spec, path):
    # A plain archive: CreateArchiveWithInfo would stamp the time of writing, and the same
    # command must give the same bytes twice. Units and up axis go into user properties.
    archive = Abc.OArchive(path)
    # Sample i at (start + i) / fps, the same frames as the PC2 / USD of the same command.
    sampling = archive.addTimeSampling(
        AbcCoreAbstract.TimeSampling(1.0 / spec["fps"], spec["start"] / spec["fps"])
    )
    top = archive.getTop()
    frames = spec["frames"]
    for m in spec["meshes"]:
        xform = AbcGeom.OXform(top, m["name"], sampling)
        user = xform.getSchema().getUserProperties()
        for key, value in spec["user_properties"]:
            Abc.OStringProperty(user, key).setValue(value)
        xform.getSchema().set(AbcGeom.XformSample())
        mesh = AbcGeom.OPolyMesh(xform, m["name"] + "Shape", sampling)
        schema = mesh.getSchema()
        n = m["point_count"]
        points = m["points"]
        extents = m["extents"]
        indices = imath.IntArrayFromBuffer(m["face_indices"])
        counts = imath.IntArray(len(indices) // 3)
        for i in range(len(counts)):
            counts[i] = 3
        uvs = AbcGeom.OV2fGeomParamSample()
        if m.get("uvs") is not None:
            # Indexed face-varying UVs (what DCCs write): the coordinates, and each corner's
            # index into them in the faces' corner order.
            values = imath.V2fArrayFromBuffer(m["uvs"].cast("B").cast("f", (len(m["uvs"]) // 2, 2)))
            uv_indices = m["uv_indices"]
            corners = imath.UnsignedIntArray(len(uv_indices))
            for i in range(len(uv_indices)):
                corners[i] = uv_indices[i]
            uvs = AbcGeom.OV2fGeomParamSample(values, corners, AbcGeom.GeometryScope.kFacevaryingScope)
        for f in range(frames):
            p = _v3(points[f * 3 * n:(f + 1) * 3 * n])
            if f == 0:
                sample = AbcGeom.OPolyMeshSchemaSample(p, indices, counts, uvs)
            else:
                sample = AbcGeom.OPolyMeshSchemaSample()
                sample.setPositions(p)
            sample.setSelfBounds(_bounds(extents[f * 6:(f + 1) * 6]))
            schema.set(sample)
    # The archive is finished when its objects go, at return.
