"""Evaluate an animated skinned/morphed glTF in Blender (an independent reader).

usage:
  blender -b --factory-startup --python tools/blender/eval_gltf.py -- \\
      FILE.glb (--frames 0,10,20 | --times 0,0.5,1) [--out result.json]
      [--fps N] [--animation NAME|INDEX] [--merge-vertices]
      [--bone-heuristic BLENDER|TEMPERANCE|FORTUNE] [--no-guess-bind-pose]

Imports FILE with Blender's own glTF importer (io_scene_gltf2, Blender 3.4),
sets each frame with scene.frame_set() and reads the depsgraph-evaluated mesh
(armature + shape keys applied by Blender) in WORLD space, converted back to
glTF Y-up so the numbers compare directly with the file / three.js.

What we found (Blender 3.4.1, io_scene_gltf2 3.4):
* time -> frame: the importer keys every sampler time t at frame t * scene.render.fps
  (no +1 offset, fps_base ignored; scene.frame_start/end are NOT changed and the
  importer does NOT set fps: factory fps is 24).  This script sets
  scene.render.fps BEFORE import (--fps, default: 1/key spacing of the file's
  first animation when it is a whole number, else 24) so keys land on integer
  frames, then measures the mapping from the imported F-curves and reports it.
* axes: import maps glTF (x, y, z) -> Blender (x, -z, y); we invert it:
  glTF = (bx, bz, -by).
* objects: a skinned glTF node becomes an EMPTY named after the node, and the
  mesh becomes a separate MESH object named after the glTF *mesh*, parented to
  the Armature object (ARMATURE modifier, one vertex group per joint).  Morph
  targets become shape keys ("Basis" + mesh.extras.targetNames).
* vertices: with merge_vertices=False (default, kept here) the importer takes,
  for each primitive in order, numpy.unique(indices) of that primitive:
  vertices keep accessor order, vertices no index refers to are DROPPED, and
  primitives are concatenated into one Blender mesh (a vertex shared by two
  primitives' accessors appears once per primitive).  We rebuild this map from
  the file (per Blender vertex: glTF primitive + accessor index) and check it
  against Blender's rest coordinates ("rest_check_max_error").
* interpolation: LINEAR samplers become LINEAR F-curves, interpolated per
  component (quaternions are lerped component-wise, not slerped), so between
  keys Blender differs slightly from glTF/three; compare at key frames.
* animations: each glTF animation becomes actions stashed on muted NLA tracks
  named after the animation; the first is made active.  --animation picks
  another by assigning its strip actions (channels it does not animate keep
  whatever value they have; baked exports animate everything).

Output JSON: { file, blender_version, fps, frame_time_mapping, animation,
  animations, actions, armatures: [{name, bone_count, bones}],
  meshes: [{ name, mesh_name, gltf_mesh, vertex_count, shape_keys,
             shape_key_count, armature, vertex_map: {primitive: [...],
             index: [...]}, rest_check_max_error,
             frames: [{frame, time_seconds, frame_time: {frame, time_seconds},
                       shape_key_values, positions: [x0, y0, z0, ...]}] }] }
"""
# Blender 3.4's glTF importer still uses numpy.bool (removed in numpy 1.24).
import numpy
numpy.bool = bool

import base64
import json
import os
import struct
import sys
import time

import bpy
import numpy as np


# ---------------------------------------------------------------- args
def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    o = {"file": None, "frames": None, "times": None, "out": None, "fps": None,
         "animation": None, "merge": False, "bone_heuristic": "TEMPERANCE", "guess_bind": True}
    i = 0
    while i < len(argv):
        a = argv[i]
        if a in ("--frames", "--times", "--out", "--fps", "--animation", "--bone-heuristic"):
            if i + 1 >= len(argv):
                die("%s needs a value" % a)
            o[a[2:].replace("-", "_")] = argv[i + 1]
            i += 2
            continue
        if a == "--merge-vertices":
            o["merge"] = True
        elif a == "--no-guess-bind-pose":
            o["guess_bind"] = False
        elif a.startswith("--"):
            die("unknown option " + a)
        elif o["file"] is None:
            o["file"] = a
        else:
            die("extra argument " + a)
        i += 1
    if not o["file"] or (o["frames"] is None) == (o["times"] is None):
        die("need FILE and exactly one of --frames / --times")
    for k in ("frames", "times"):
        if o[k] is not None:
            o[k] = [float(x) for x in o[k].split(",") if x.strip()]
    if o["fps"] is not None:
        o["fps"] = int(o["fps"])
    return o


def die(msg, code=2):
    sys.stderr.write("eval_gltf: %s\n" % msg)
    sys.stderr.write("usage: blender -b --factory-startup --python tools/blender/eval_gltf.py -- "
                     "FILE.glb (--frames F,.. | --times T,..) [--out result.json] [--fps N] "
                     "[--animation NAME|INDEX] [--merge-vertices] [--bone-heuristic H] [--no-guess-bind-pose]\n")
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)  # sys.exit inside --python only aborts the script, Blender would exit 0


# ---------------------------------------------------------------- minimal glTF reader
# Only what we need to predict Blender's vertex order and the key spacing;
# independent of the importer and of garmentbake.
CTYPE = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


def read_gltf(path):
    data = open(path, "rb").read()
    buffers = []
    if data[:4] == b"glTF":
        off, js, binchunk = 12, None, None
        while off < len(data):
            ln, typ = struct.unpack_from("<II", data, off)
            chunk = data[off + 8: off + 8 + ln]
            if typ == 0x4E4F534A:
                js = json.loads(chunk.decode("utf8"))
            elif typ == 0x004E4942:
                binchunk = chunk
            off += 8 + ln
    else:
        js, binchunk = json.loads(data.decode("utf8")), None
    for b in js.get("buffers", []):
        uri = b.get("uri")
        if uri is None:
            buffers.append(binchunk)
        elif uri.startswith("data:"):
            buffers.append(base64.b64decode(uri.split(",", 1)[1]))
        else:
            from urllib.parse import unquote
            buffers.append(open(os.path.join(os.path.dirname(path), unquote(uri)), "rb").read())
    return js, buffers


def accessor(js, buffers, idx):
    """Decode a (non-sparse) accessor to an (count, ncomp) array."""
    a = js["accessors"][idx]
    n, dt = NCOMP[a["type"]], np.dtype(CTYPE[a["componentType"]])
    if "bufferView" not in a or "sparse" in a:
        return None
    bv = js["bufferViews"][a["bufferView"]]
    buf = buffers[bv["buffer"]]
    base = bv.get("byteOffset", 0) + a.get("byteOffset", 0)
    stride = bv.get("byteStride", n * dt.itemsize)
    if stride == n * dt.itemsize:  # tightly packed: one read
        return np.frombuffer(buf, dt, a["count"] * n, base).reshape(-1, n).copy()
    out = np.empty((a["count"], n), dt)
    for i in range(a["count"]):  # interleaved (byteStride) data
        out[i] = np.frombuffer(buf, dt, n, base + i * stride)
    return out


def blender_vertex_map(js, buffers, mesh_idx):
    """(primitive, accessor index) of each Blender vertex, like the 3.4 importer."""
    prims, idxs = [], []
    for pi, prim in enumerate(js["meshes"][mesh_idx]["primitives"]):
        if "POSITION" not in prim["attributes"]:
            continue
        if "indices" in prim:
            ind = accessor(js, buffers, prim["indices"]).reshape(-1).astype(np.int64)
        else:
            ind = np.arange(js["accessors"][prim["attributes"]["POSITION"]]["count"])
        if prim.get("mode", 4) == 4:
            ind = ind[: len(ind) // 3 * 3]  # importer drops a trailing partial triangle
        u = np.unique(ind)
        prims += [pi] * len(u)
        idxs += u.tolist()
    return prims, idxs


def guess_fps(js, buffers):
    """Frames per second from the key spacing of the first animation."""
    try:
        s = js["animations"][0]["samplers"][0]
        t = accessor(js, buffers, s["input"]).reshape(-1).astype(np.float64)
        dt = np.median(np.diff(t))
        fps = 1.0 / dt
        if abs(fps - round(fps)) < 1e-3:
            return int(round(fps))
    except Exception:
        pass
    return None


# ---------------------------------------------------------------- helpers
def to_gltf_axes(p):
    """Blender Z-up (x, y, z) -> glTF Y-up (x, z, -y); inverse of the importer's map."""
    return np.stack([p[:, 0], p[:, 2], -p[:, 1]], axis=1)


def set_frame(scene, f):
    fi = int(np.floor(f))
    scene.frame_set(fi, subframe=float(f - fi))


def select_animation(track_name):
    """Activate one imported animation, like the importer's restore_animation."""
    datablocks = [o for o in bpy.data.objects] + [k for k in bpy.data.shape_keys]
    for d in datablocks:
        ad = getattr(d, "animation_data", None)
        if not ad:
            continue
        ad.action = None
        for tr in ad.nla_tracks:
            if tr.name == track_name and tr.strips:
                ad.action = tr.strips[0].action


def track_actions(track_name):
    """Actions the importer stashed on NLA tracks named after one animation."""
    out = []
    for d in list(bpy.data.objects) + list(bpy.data.shape_keys):
        ad = getattr(d, "animation_data", None)
        for tr in (ad.nla_tracks if ad else []):
            if tr.name == track_name:
                out += [st.action for st in tr.strips if st.action]
    return out


def measured_mapping(js, buffers, anim_idx, track_name, fps):
    """Fit frame = a * t + b from the imported F-curve keys vs the file's key times."""
    anim = js["animations"][anim_idx]
    t_all = np.concatenate([accessor(js, buffers, s["input"]).reshape(-1) for s in anim["samplers"]])
    tmin, tmax = float(t_all.min()), float(t_all.max())
    frames = [kp.co[0] for a in track_actions(track_name) for fc in a.fcurves for kp in fc.keyframe_points]
    if not frames:
        return None
    fmin, fmax = float(min(frames)), float(max(frames))
    a = (fmax - fmin) / (tmax - tmin) if tmax > tmin else float(fps)
    b = fmin - a * tmin
    return {"first_key_time": tmin, "first_key_frame": fmin, "last_key_time": tmax,
            "last_key_frame": fmax, "frames_per_second": a, "frame_offset": b,
            "rule": "frame = time_seconds * scene.render.fps (importer), measured a=%.6g b=%.6g" % (a, b)}


# ---------------------------------------------------------------- main
def main():
    o = parse_args()
    t_start = time.time()
    js, buffers = read_gltf(o["file"])

    bpy.ops.wm.read_factory_settings(use_empty=True)  # no default cube/camera/light
    scene = bpy.context.scene
    fps = o["fps"] or guess_fps(js, buffers) or scene.render.fps
    scene.render.fps, scene.render.fps_base = fps, 1.0  # importer reads fps at import time

    bpy.ops.import_scene.gltf(
        filepath=os.path.abspath(o["file"]),
        merge_vertices=o["merge"],  # False: keep glTF vertices (no co-located merge)
        import_shading="NORMALS",
        bone_heuristic=o["bone_heuristic"],  # bone tails only; does not move vertices
        guess_original_bind_pose=o["guess_bind"],
    )

    anims = js.get("animations", [])
    track_names, used = [], set()
    for i, a in enumerate(anims):  # same naming rule as the importer
        name = a.get("name") or "Anim_%d" % i
        base, k = name, 0
        while name in used:
            k += 1
            name = "%s.%03d" % (base, k)
        used.add(name)
        track_names.append(name)
    anim_idx = None
    if anims:
        if o["animation"] is None:
            anim_idx = 0
        elif o["animation"].isdigit():
            anim_idx = int(o["animation"])
        elif o["animation"] in track_names:
            anim_idx = track_names.index(o["animation"])
        else:
            die("animation %s not found (have %s)" % (o["animation"], track_names))
        if anim_idx != 0:
            select_animation(track_names[anim_idx])

    mapping = (measured_mapping(js, buffers, anim_idx, track_names[anim_idx], fps)
               if anim_idx is not None else None)
    a_fit = mapping["frames_per_second"] if mapping else float(fps)
    b_fit = mapping["frame_offset"] if mapping else 0.0
    frames = o["frames"] if o["frames"] is not None else [t * a_fit + b_fit for t in o["times"]]

    gltf_mesh_by_name = {m.get("name"): i for i, m in enumerate(js.get("meshes", []))}
    mesh_objs = [ob for ob in bpy.data.objects if ob.type == "MESH"]
    recs = []
    for ob in mesh_objs:
        me = ob.data
        arm = next((m.object for m in ob.modifiers if m.type == "ARMATURE" and m.object), None)
        keys = [k.name for k in me.shape_keys.key_blocks] if me.shape_keys else []
        rec = {"name": ob.name, "mesh_name": me.name, "gltf_mesh": gltf_mesh_by_name.get(me.name),
               "vertex_count": len(me.vertices), "shape_keys": keys[1:],
               "shape_key_count": max(len(keys) - 1, 0), "armature": arm.name if arm else None,
               "vertex_map": None, "rest_check_max_error": None, "frames": []}
        # predicted vertex order vs Blender's rest coordinates (basis shape, local space)
        if rec["gltf_mesh"] is not None:
            prims, idxs = blender_vertex_map(js, buffers, rec["gltf_mesh"])
            rec["vertex_map"] = {"primitive": prims, "index": idxs}
            if len(idxs) == len(me.vertices):
                co = np.empty(3 * len(me.vertices))
                me.vertices.foreach_get("co", co)
                got = to_gltf_axes(co.reshape(-1, 3))
                gp = js["meshes"][rec["gltf_mesh"]]["primitives"]
                pos = {pi: accessor(js, buffers, gp[pi]["attributes"]["POSITION"]) for pi in set(prims)}
                if all(v is not None for v in pos.values()):
                    want = np.array([pos[p][i] for p, i in zip(prims, idxs)], np.float64)
                    rec["rest_check_max_error"] = float(np.abs(got - want).max()) if len(want) else 0.0
        recs.append((ob, rec))

    for f in frames:
        set_frame(scene, f)
        dg = bpy.context.evaluated_depsgraph_get()
        for ob, rec in recs:
            ev = ob.evaluated_get(dg)
            m = ev.to_mesh()  # armature + shape keys applied, object space
            co = np.empty(3 * len(m.vertices))
            m.vertices.foreach_get("co", co)
            ev.to_mesh_clear()
            mw = np.array(ev.matrix_world, dtype=np.float64)
            co = co.reshape(-1, 3) @ mw[:3, :3].T + mw[:3, 3]  # world space
            t = (f - b_fit) / a_fit
            kb = ob.data.shape_keys.key_blocks if ob.data.shape_keys else []
            rec["frames"].append({
                "frame": f, "time_seconds": t, "frame_time": {"frame": f, "time_seconds": t},
                "shape_key_values": {k.name: k.value for k in list(kb)[1:]},
                "positions": to_gltf_axes(co).reshape(-1).tolist(),
            })

    arms = [{"name": ob.name, "bone_count": len(ob.data.bones), "bones": [b.name for b in ob.data.bones]}
            for ob in bpy.data.objects if ob.type == "ARMATURE"]
    result = {
        "file": o["file"], "blender_version": bpy.app.version_string,
        "fps": fps, "frame_time_mapping": mapping,
        "animation": track_names[anim_idx] if anim_idx is not None else None,
        "animations": track_names, "actions": [a.name for a in bpy.data.actions],
        "objects": [{"name": ob.name, "type": ob.type, "parent": ob.parent.name if ob.parent else None}
                    for ob in bpy.data.objects],
        "armatures": arms, "has_armature": bool(arms),
        "import_settings": {"merge_vertices": o["merge"], "bone_heuristic": o["bone_heuristic"],
                            "guess_original_bind_pose": o["guess_bind"]},
        "elapsed_s": round(time.time() - t_start, 3),
        "meshes": [r for _, r in recs],
    }
    text = json.dumps(result)
    if o["out"]:
        with open(o["out"], "w") as fh:
            fh.write(text)
        sys.stderr.write("eval_gltf: %s: %d mesh(es), %d frame(s), %.2fs -> %s\n"
                         % (o["file"], len(recs), len(frames), result["elapsed_s"], o["out"]))
    else:
        sys.stdout.write(text + "\n")


try:
    main()
except SystemExit:
    raise
except BaseException:
    import traceback
    traceback.print_exc()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(1)  # make failures visible as a non-zero exit code
