"""Import an Alembic file with Blender's own Alembic importer and report what a DCC user gets.

usage (Blender as a Python module, PyPI `bpy`, Python 3.11: `bash scripts/setup_bpy.sh`; the
Debian Blender 3.4 is built without Alembic):
  target/bpy-venv/bin/python tools/blender/eval_abc.py FILE.abc --fps 30 [--frames 0,10,20 | --all] [--out result.json]

The scene runs at --fps before the import, so the importer's frame range is the archive's time
range in frames at that rate (the MeshSequenceCache reads time frame / fps). Reports the scene's
frame range and, per mesh object (the PolyMeshes, with their cache modifier), the depsgraph-evaluated
world positions at the frames asked, mapped back from Blender's Z-up to the file's Y-up:
file = (bx, bz, -by).

Output JSON: { file, blender_version, scene: {fps, frame_start, frame_end}, meshes: [{name,
  vertex_count, face_count, uv_layers, cache_modifier, faces, frames: [{frame, positions}]}] }
"""
import argparse
import json
import sys

import bpy
import numpy as np


def main(argv):
    ap = argparse.ArgumentParser()
    ap.add_argument("file")
    ap.add_argument("--fps", type=float, required=True)
    ap.add_argument("--frames")
    ap.add_argument("--all", action="store_true")
    ap.add_argument("--out")
    a = ap.parse_args(argv)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = int(round(a.fps))
    scene.render.fps_base = scene.render.fps / a.fps
    result = bpy.ops.wm.alembic_import(filepath=a.file, set_frame_range=True, as_background_job=False)
    if "FINISHED" not in result:
        sys.stderr.write("eval_abc: import failed: %s\n" % result)
        return 2
    if a.all:
        frames = list(range(scene.frame_start, scene.frame_end + 1))
    else:
        frames = [int(f) for f in a.frames.split(",")]
    out = {
        "file": a.file,
        "blender_version": bpy.app.version_string,
        "scene": {"fps": scene.render.fps / scene.render.fps_base,
                  "frame_start": scene.frame_start, "frame_end": scene.frame_end},
        "meshes": [],
    }
    meshes = sorted((ob for ob in scene.objects if ob.type == "MESH"), key=lambda o: o.name)
    for ob in meshes:
        out["meshes"].append({
            "name": ob.name,
            "vertex_count": len(ob.data.vertices),
            "face_count": len(ob.data.polygons),
            "uv_layers": [uv.name for uv in ob.data.uv_layers],
            "cache_modifier": any(m.type == "MESH_SEQUENCE_CACHE" for m in ob.modifiers),
            # Vertex indices of every face as Blender orders them (its front side).
            "faces": [list(p.vertices) for p in ob.data.polygons],
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
