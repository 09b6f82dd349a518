"""Play a PC2 or MDD point cache on an OBJ in Blender (an independent reader).

usage:
  blender -b --factory-startup --python tools/blender/eval_pc2.py -- \\
      MESH.obj CACHE.pc2 --frames 0,1,2 [--out result.json]
      [--importer legacy|new] [--frame-start F]

Imports MESH.obj, adds a Mesh Cache modifier (format PC2, or MDD for a .mdd
CACHE: big-endian frame count, point count, frame times, points) reading it,
and reports the depsgraph-evaluated positions at the given scene frames in
the OBJ/PC2 file's own Y-up coordinates, so they compare 1:1 with the cache.

What we found (Blender 3.4.1):
* OBJ import (both importers, default axis_forward -Z / axis_up Y) does NOT
  touch the vertex data: it puts the Y-up -> Z-up rotation (+90 deg about X)
  on the object's matrix_world.  The Mesh Cache modifier overwrites the mesh
  data in object space, so its own axes must stay at the identity (forward
  POS_Y, up POS_Z, the defaults): the cache then lives in the same (file)
  frame as the OBJ data and the object matrix rotates both.  Setting the
  cache axes to NEG_Z/POS_Y would rotate twice.  We read world positions
  (matrix_world @ co) and map Blender Z-up back to Y-up: file = (bx, bz, -by).
* vertex order: the legacy Python importer (bpy.ops.import_scene.obj,
  split_mode='OFF', the default here) keeps the file's vertex order and also
  keeps vertices no face uses.  The new C++ importer (wm.obj_import) keeps the
  order but DROPS unused vertices, which breaks the cache's point count.
* frame -> sample (time_mode FRAME, play_mode SCENE, the defaults):
  sample = scene_frame - modifier.frame_start (0 by default here), linear
  between samples, clamped to [0, numSamples-1].  The header's startFrame and
  sampleRate are IGNORED in this mode.  (time_mode TIME does use them but
  divides by fps twice in 3.4, so we do not use it.)
* If the OBJ vertex count differs from the cache's numPoints the modifier
  silently leaves the mesh unchanged; we fail loudly instead.

Output JSON: { obj, pc2, blender_version, header: {version, num_points,
  start_frame, sample_rate, num_samples}, importer, object_matrix_world,
  cache_axes, frame_start, vertex_count,
  frames: [{frame, cache_sample, positions: [x0, y0, z0, ...]}] }
"""
import json
import os
import struct
import sys
import time

import bpy
import numpy as np


def die(msg, code=2):
    sys.stderr.write("eval_pc2: %s\n" % msg)
    if code == 2:
        sys.stderr.write("usage: blender -b --factory-startup --python tools/blender/eval_pc2.py -- "
                         "MESH.obj CACHE.pc2 --frames F,.. [--out result.json] "
                         "[--importer legacy|new] [--frame-start F]\n")
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)  # sys.exit inside --python only aborts the script, Blender would exit 0


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    o = {"files": [], "frames": None, "out": None, "importer": "legacy", "frame_start": 0.0}
    i = 0
    while i < len(argv):
        a = argv[i]
        if a in ("--frames", "--out", "--importer", "--frame-start"):
            if i + 1 >= len(argv):
                die("%s needs a value" % a)
            o[a[2:].replace("-", "_")] = argv[i + 1]
            i += 2
            continue
        if a.startswith("--"):
            die("unknown option " + a)
        o["files"].append(a)
        i += 1
    if len(o["files"]) != 2 or o["frames"] is None:
        die("need MESH.obj CACHE.pc2 --frames ...")
    if o["importer"] not in ("legacy", "new"):
        die("--importer must be legacy or new")
    o["frames"] = [float(x) for x in o["frames"].split(",") if x.strip()]
    o["frame_start"] = float(o["frame_start"])
    return o


def read_mdd_header(path):
    """MDD: big-endian i32 frames, i32 points, then f32 times; reported in the PC2 header's terms."""
    with open(path, "rb") as f:
        head = f.read(8)
        if len(head) < 8:
            die("%s is not an MDD file" % path, 1)
        frames, n = struct.unpack(">ii", head)
        times = struct.unpack(">%df" % frames, f.read(4 * frames)) if frames > 0 else ()
    return {"version": "mdd", "num_points": n, "start_frame": 0.0, "sample_rate": 1.0,
            "num_samples": frames, "times": list(times[:3])}


def read_pc2_header(path):
    if path.lower().endswith(".mdd"):
        return read_mdd_header(path)
    with open(path, "rb") as f:
        head = f.read(32)
    if len(head) < 32 or head[:12] != b"POINTCACHE2\0":
        die("%s is not a PC2 file" % path, 1)
    version, n, start, rate, ns = struct.unpack("<iiffi", head[12:32])
    return {"version": version, "num_points": n, "start_frame": start, "sample_rate": rate, "num_samples": ns}


def to_file_axes(p):
    """Blender Z-up (x, y, z) -> Y-up file (x, z, -y); inverse of the OBJ import axes."""
    return np.stack([p[:, 0], p[:, 2], -p[:, 1]], axis=1)


def main():
    o = parse_args()
    t_start = time.time()
    obj_path, pc2_path = (os.path.abspath(p) for p in o["files"])
    header = read_pc2_header(pc2_path)

    bpy.ops.wm.read_factory_settings(use_empty=True)  # no default cube/camera/light
    if o["importer"] == "legacy":
        # split_mode OFF = one object, file vertex order, unused vertices kept
        bpy.ops.import_scene.obj(filepath=obj_path, split_mode="OFF", axis_forward="-Z", axis_up="Y")
    else:
        bpy.ops.wm.obj_import(filepath=obj_path, forward_axis="NEGATIVE_Z", up_axis="Y")
    meshes = [ob for ob in bpy.data.objects if ob.type == "MESH"]
    if len(meshes) != 1:
        die("expected one mesh object from %s, got %d" % (obj_path, len(meshes)), 1)
    ob = meshes[0]
    nverts = len(ob.data.vertices)
    if nverts != header["num_points"]:
        die("OBJ has %d vertices but PC2 has %d points (Mesh Cache would do nothing)"
            % (nverts, header["num_points"]), 1)

    md = ob.modifiers.new("pc2", "MESH_CACHE")
    md.cache_format = "MDD" if pc2_path.lower().endswith(".mdd") else "PC2"
    md.filepath = pc2_path
    md.time_mode = "FRAME"  # sample = frame - frame_start (header start/rate ignored)
    md.play_mode = "SCENE"
    md.frame_start = o["frame_start"]
    md.frame_scale = 1.0
    md.interpolation = "LINEAR"
    md.deform_mode = "OVERWRITE"
    md.forward_axis, md.up_axis = "POS_Y", "POS_Z"  # identity: cache is in the OBJ data's frame

    scene = bpy.context.scene
    frames = []
    for f in o["frames"]:
        fi = int(np.floor(f))
        scene.frame_set(fi, subframe=float(f - fi))
        dg = bpy.context.evaluated_depsgraph_get()
        ev = ob.evaluated_get(dg)
        m = ev.to_mesh()
        co = np.empty(3 * len(m.vertices))
        m.vertices.foreach_get("co", co)
        ev.to_mesh_clear()
        mw = np.array(ev.matrix_world, dtype=np.float64)
        world = co.reshape(-1, 3) @ mw[:3, :3].T + mw[:3, 3]
        sample = min(max(f - o["frame_start"], 0.0), header["num_samples"] - 1.0)
        frames.append({"frame": f, "cache_sample": sample,
                       "positions": to_file_axes(world).reshape(-1).tolist()})

    result = {
        "obj": o["files"][0], "pc2": o["files"][1], "blender_version": bpy.app.version_string,
        "header": header, "importer": o["importer"],
        "object_matrix_world": [list(r) for r in ob.matrix_world],
        "cache_axes": {"forward": md.forward_axis, "up": md.up_axis},
        "frame_start": o["frame_start"],
        "frame_mapping": "cache_sample = clamp(frame - frame_start, 0, num_samples-1), linear; header start/rate ignored",
        "vertex_count": nverts, "elapsed_s": round(time.time() - t_start, 3),
        "frames": frames,
    }
    text = json.dumps(result)
    if o["out"]:
        with open(o["out"], "w") as fh:
            fh.write(text)
        sys.stderr.write("eval_pc2: %s + %s: %d verts, %d frame(s), %.2fs -> %s\n"
                         % (o["files"][0], o["files"][1], nverts, len(frames), result["elapsed_s"], o["out"]))
    else:
        sys.stdout.write(text + "\n")


try:
    main()
except BaseException:
    import traceback
    traceback.print_exc()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(1)  # make failures visible as a non-zero exit code
