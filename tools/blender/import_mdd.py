"""Read an MDD with Blender's own MDD importer (the bundled `io_shape_mdd` add-on: one shape key
per frame, keyed 0 -> 1 -> 0) onto an OBJ, and report what Blender shows (an independent reader).

usage:
  blender -b --factory-startup --python tools/blender/import_mdd.py -- \\
      MESH.obj CACHE.mdd --frames 0,5,100 [--out result.json]

What Blender 3.4's add-on does (import_mdd.py / export_mdd.py, read here): big-endian frame and
point counts, the frame times are read and IGNORED (shape key i is keyed at frame_start + i *
frame_step), and every point's x, y, z goes as it is into the shape key, i.e. into the object's
own (local) coordinates: no axis swap and no handedness flip (the exporter's "flip y and z"
matrix is commented out and replaced by the identity). So the MDD lives in the frame of the
mesh data it is loaded on: on an OBJ imported Y-up (the importer puts the Y-up -> Z-up turn on
the object's matrix_world, the data keep the file's axes), a Y-up right-handed MDD stands up.

Reported per frame: `local` (the evaluated mesh's coordinates, the MDD's own frame) and `world`
(matrix_world applied, Blender's Z-up), and the mean dot product between the faces' normals in
Blender's world and our winding's normals of the file points turned (x, y, z) -> (x, -z, y):
+1 when the data keep their handedness and winding, -1 for a mirrored read.
"""

import json
import os
import struct
import sys
import time

import bpy
import numpy as np


def die(msg, code=2):
    sys.stderr.write("import_mdd: %s\n" % msg)
    sys.stderr.flush()
    os._exit(code)


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    o = {"files": [], "frames": [0], "out": None}
    i = 0
    while i < len(argv):
        a = argv[i]
        if a in ("--frames", "--out"):
            if i + 1 >= len(argv):
                die("%s needs a value" % a)
            v = argv[i + 1]
            o[a[2:]] = [int(x) for x in v.split(",")] if a == "--frames" else v
            i += 2
        else:
            o["files"].append(a)
            i += 1
    if len(o["files"]) != 2:
        die("give MESH.obj and CACHE.mdd")
    return o


def face_normals(p, faces):
    a, b, c = p[faces[:, 0]], p[faces[:, 1]], p[faces[:, 2]]
    n = np.cross(b - a, c - a)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)


def main():
    o = parse_args()
    t0 = time.time()
    obj_path, mdd_path = (os.path.abspath(p) for p in o["files"])
    with open(mdd_path, "rb") as f:
        frames, points = struct.unpack(">2i", f.read(8))
        times = struct.unpack(">%df" % frames, f.read(4 * frames))
        data = np.frombuffer(f.read(12 * frames * points), dtype=">f4").reshape(frames, points, 3)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.preferences.addon_enable(module="io_shape_mdd")
    bpy.ops.import_scene.obj(filepath=obj_path, split_mode="OFF", axis_forward="-Z", axis_up="Y")
    meshes = [ob for ob in bpy.data.objects if ob.type == "MESH"]
    if len(meshes) != 1:
        die("expected one mesh object from %s, got %d" % (obj_path, len(meshes)), 1)
    ob = meshes[0]
    if len(ob.data.vertices) != points:
        die("OBJ has %d vertices, the MDD %d points" % (len(ob.data.vertices), points), 1)
    bpy.context.view_layer.objects.active = ob
    ob.select_set(True)
    t1 = time.time()
    bpy.ops.import_shape.mdd(filepath=mdd_path, frame_start=0, frame_step=1)
    t_import = time.time() - t1

    faces = np.array([list(p.vertices) for p in ob.data.polygons if len(p.vertices) == 3])
    scene = bpy.context.scene
    out = []
    for fr in o["frames"]:
        scene.frame_set(fr)
        dg = bpy.context.evaluated_depsgraph_get()
        ev = ob.evaluated_get(dg)
        m = ev.to_mesh()
        co = np.empty(3 * len(m.vertices))
        m.vertices.foreach_get("co", co)
        ev.to_mesh_clear()
        local = co.reshape(-1, 3)
        mw = np.array(ev.matrix_world, dtype=np.float64)
        world = local @ mw[:3, :3].T + mw[:3, 3]
        ours = data[fr].astype(np.float64)
        turned = np.stack([ours[:, 0], -ours[:, 2], ours[:, 1]], axis=1)
        dots = np.sum(face_normals(world, faces) * face_normals(turned, faces), axis=1)
        out.append({
            "frame": fr,
            "local_max_abs": float(np.abs(local - ours).max()),
            "world_vs_turned_max_abs": float(np.abs(world - turned).max()),
            "mean_normal_dot": float(dots.mean()),
        })
    result = {
        "blender_version": bpy.app.version_string,
        "frames_in_file": frames, "points": points,
        "times": [times[0], times[-1]],
        "shape_keys": len(ob.data.shape_keys.key_blocks) - 1,
        "object_matrix_world": [list(r) for r in ob.matrix_world],
        "import_s": round(t_import, 2), "elapsed_s": round(time.time() - t0, 2),
        "frames": out,
    }
    text = json.dumps(result)
    if o["out"]:
        with open(o["out"], "w") as fh:
            fh.write(text)
    sys.stdout.write(text + "\n")


try:
    main()
except BaseException:
    import traceback
    traceback.print_exc()
    sys.stdout.flush()
    os._exit(1)
