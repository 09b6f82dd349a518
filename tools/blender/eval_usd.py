"""Import a USD file with Blender's own USD importer and report what a DCC user would get.

usage (Blender as a Python module, PyPI `bpy`, Python 3.11; see docs/usd.md):
  target/bpy-venv/bin/python tools/blender/eval_usd.py FILE.usdc --frames 0,10,20 [--out result.json]

Reports the armatures (bone counts, whether an action animates them), the meshes (vertex count,
shape-key names, whether the shape keys are animated, armature modifier) and the depsgraph-evaluated
world positions of every mesh at the given scene frames, mapped back from Blender's Z-up to the
file's Y-up: file = (bx, bz, -by). The USD importer maps time code t to scene frame t.

Output JSON: { file, blender_version, scene: {fps, frame_start, frame_end}, armatures: [{name,
  bone_count, animated}], meshes: [{name, vertex_count, shape_keys, shape_keys_animated,
  armature_modifier, frames: [{frame, positions: [x0, y0, z0, ...]}]}] }
"""
import argparse
import json
import sys

import bpy
import numpy as np


def main(argv):
    ap = argparse.ArgumentParser()
    ap.add_argument("file")
    ap.add_argument("--frames", required=True)
    ap.add_argument("--out")
    a = ap.parse_args(argv)
    frames = [int(f) for f in a.frames.split(",")]

    bpy.ops.wm.read_factory_settings(use_empty=True)
    result = bpy.ops.wm.usd_import(filepath=a.file, import_blendshapes=True, import_skeletons=True,
                                   set_frame_range=True)
    if "FINISHED" not in result:
        sys.stderr.write("eval_usd: import failed: %s\n" % result)
        return 2
    scene = bpy.context.scene
    out = {
        "file": a.file,
        "blender_version": bpy.app.version_string,
        "scene": {"fps": scene.render.fps / scene.render.fps_base,
                  "frame_start": scene.frame_start, "frame_end": scene.frame_end},
        "armatures": [],
        "meshes": [],
    }
    for ob in scene.objects:
        if ob.type == "ARMATURE":
            out["armatures"].append({
                "name": ob.name,
                "bone_count": len(ob.data.bones),
                "animated": bool(ob.animation_data and ob.animation_data.action),
            })
    meshes = [ob for ob in scene.objects if ob.type == "MESH"]
    for ob in meshes:
        keys = ob.data.shape_keys
        out["meshes"].append({
            "name": ob.name,
            "vertex_count": len(ob.data.vertices),
            "shape_keys": [k.name for k in keys.key_blocks] if keys else [],
            "shape_keys_animated": bool(keys and keys.animation_data and keys.animation_data.action),
            "armature_modifier": any(m.type == "ARMATURE" for m in ob.modifiers),
            "frames": [],
        })
    for f in frames:
        scene.frame_set(f)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        for ob, entry in zip(meshes, out["meshes"]):
            ev = ob.evaluated_get(depsgraph)
            mesh = ev.to_mesh()
            co = np.empty(len(mesh.vertices) * 3, dtype=np.float64)
            mesh.vertices.foreach_get("co", co)
            ev.to_mesh_clear()
            m = np.array(ev.matrix_world, dtype=np.float64)
            world = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
            y_up = np.stack([world[:, 0], world[:, 2], -world[:, 1]], axis=1)
            entry["frames"].append({"frame": f, "positions": y_up.ravel().tolist()})
    text = json.dumps(out)
    if a.out:
        with open(a.out, "w") as fh:
            fh.write(text)
    else:
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
