"""garmentbake simulate: Blender's cloth solver on a body that garmentbake posed.

Run by `garmentbake simulate` (embedded in the binary, written next to the job):
  blender -b --factory-startup --python cloth.py -- JOB_DIR

JOB_DIR/job.json names everything; the meshes and per-frame points are raw little-endian arrays in
garmentbake's frame (metres, Y-up). Objects get the Y-up -> Z-up rotation as their matrix (as the
OBJ importer does), so Blender's gravity (-Z) pulls along -Y in our data, and the Mesh Cache
modifiers (identity axes, frame mode: sample = frame - frame_start) replay our points in object
space. Results are read back in object space: no axis conversion on our side.

Blender's cloth ignores the scene's frame rate: one frame is sqrt(0.001) s of gravity (a free fall
measured 4.44 m after 30 frames at any fps); `time_scale` maps the clip's frame time onto it.

Writes JOB_DIR/garment.f32 (frames x vertices x 3) and JOB_DIR/result.json; prints "frame N" per
simulated frame for the progress bar. Stops at the first frame with a non-finite point or a
vertex faster than the job's speed limit (result.json names it).
"""
import json
import math
import os
import sys
import time

import bpy
import numpy as np


def die(msg):
    sys.stderr.write("cloth.py: %s\n" % msg)
    sys.stderr.flush()
    os._exit(3)  # sys.exit inside --python only ends the script; Blender would exit 0


def mesh_object(name, positions, triangles, scene):
    me = bpy.data.meshes.new(name)
    me.vertices.add(len(positions))
    me.vertices.foreach_set("co", positions.reshape(-1))
    me.loops.add(triangles.size)
    me.loops.foreach_set("vertex_index", triangles.reshape(-1))
    me.polygons.add(len(triangles))
    me.polygons.foreach_set("loop_start", np.arange(0, triangles.size, 3, dtype=np.int32))
    me.polygons.foreach_set("loop_total", np.full(len(triangles), 3, dtype=np.int32))
    me.update(calc_edges=True)
    me.validate(verbose=False)
    if len(me.vertices) != len(positions):
        die("%s: Blender dropped vertices (%d of %d kept)" % (name, len(me.vertices), len(positions)))
    ob = bpy.data.objects.new(name, me)
    scene.collection.objects.link(ob)
    # Y-up data, Z-up world: +90 degrees about X.
    ob.rotation_euler = (math.pi / 2, 0.0, 0.0)
    return ob


def read_mesh(job_dir, spec):
    points = np.fromfile(os.path.join(job_dir, spec["points"]), dtype="<f4").reshape(-1, 3)
    tris = np.fromfile(os.path.join(job_dir, spec["triangles"]), dtype="<u4").reshape(-1, 3)
    if len(points) != spec["vertices"]:
        die("%s: %d points, job says %d" % (spec["points"], len(points), spec["vertices"]))
    return points, tris.astype(np.int32)


def replay(ob, pc2_path, first_frame):
    """Mesh Cache in frame mode: sample = frame - frame_start; axes identity (object space)."""
    md = ob.modifiers.new("garmentbake_cache", "MESH_CACHE")
    md.cache_format = "PC2"
    md.filepath = pc2_path
    md.time_mode = "FRAME"
    md.play_mode = "SCENE"
    md.frame_start = float(first_frame)
    md.frame_scale = 1.0
    md.interpolation = "LINEAR"
    md.deform_mode = "OVERWRITE"
    md.forward_axis, md.up_axis = "POS_Y", "POS_Z"
    return md


def setup_body(ob, c):
    ob.modifiers.new("garmentbake_collision", "COLLISION")  # last in the stack: collides with the cached pose
    col = ob.collision
    col.thickness_outer = c["body_thickness"]
    col.thickness_inner = 0.2 * c["body_thickness"] + 0.001
    col.cloth_friction = c["friction"]
    col.damping = 0.0
    col.use_culling = True
    col.use_normal = False


def setup_cloth(ob, c, pinned, frames, first_frame, time_scale):
    group = ob.vertex_groups.new(name="pinned")
    if pinned:
        group.add([int(v) for v in pinned], 1.0, "REPLACE")
    md = ob.modifiers.new("garmentbake_cloth", "CLOTH")
    s = md.settings
    s.quality = c["quality"]
    s.time_scale = time_scale
    s.mass = c["mass"]
    s.air_damping = c["air_damping"]
    s.tension_stiffness = c["tension"]
    s.compression_stiffness = c["compression"]
    s.shear_stiffness = c["shear"]
    s.bending_stiffness = c["bending"]
    s.tension_damping = c["tension_damping"]
    s.compression_damping = c["compression_damping"]
    s.shear_damping = c["shear_damping"]
    s.bending_damping = c["bending_damping"]
    s.vertex_group_mass = "pinned"
    s.pin_stiffness = 1.0
    s.use_internal_springs = False
    s.use_pressure = False
    k = md.collision_settings
    k.use_collision = True
    k.collision_quality = c["collision_quality"]
    k.distance_min = c["distance"]
    k.impulse_clamp = 0.0
    k.use_self_collision = c["self_collision"]
    k.self_distance_min = c["self_distance"]
    k.self_friction = 5.0
    k.self_impulse_clamp = 0.0
    cache = md.point_cache
    cache.frame_start = first_frame
    cache.frame_end = first_frame + frames - 1
    return md


def evaluated_points(ob, n):
    ev = ob.evaluated_get(bpy.context.evaluated_depsgraph_get())
    m = ev.to_mesh()
    if len(m.vertices) != n:
        die("evaluated garment has %d vertices, expected %d" % (len(m.vertices), n))
    co = np.empty(3 * n, dtype=np.float32)
    m.vertices.foreach_get("co", co)
    ev.to_mesh_clear()
    return co.reshape(-1, 3)


def main():
    job_dir = sys.argv[sys.argv.index("--") + 1]
    with open(os.path.join(job_dir, "job.json")) as f:
        job = json.load(f)
    c = job["cloth"]
    frames = job["frames"]
    first = 1  # Blender's cloth cache starts at frame >= 1; sample 0 of both caches plays there
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = max(1, int(round(job["fps"])))
    scene.frame_start, scene.frame_end = first, first + frames - 1

    bp, bt = read_mesh(job_dir, job["body"])
    body = mesh_object("body", bp, bt, scene)
    replay(body, os.path.join(job_dir, job["body"]["cache"]), first)
    setup_body(body, c)

    gp, gt = read_mesh(job_dir, job["garment"])
    garment = mesh_object("garment", gp, gt, scene)
    replay(garment, os.path.join(job_dir, job["garment"]["cache"]), first)
    setup_cloth(garment, c, job["pinned"], frames, first, job["time_scale"])

    n = len(gp)
    dt = 1.0 / job["fps"]
    limit = job["speed_limit"]
    out_path = os.path.join(job_dir, "garment.f32")
    result = {"blender_version": bpy.app.version_string, "frames_done": 0, "failure": None}
    started = time.time()
    previous = None
    with open(out_path, "wb") as out:
        for i in range(frames):
            scene.frame_set(first + i)  # stepping forward from the start frame simulates each frame once
            p = evaluated_points(garment, n)
            failure = None
            if not np.isfinite(p).all():
                failure = "non-finite vertex positions"
            elif previous is not None:
                speed = float(np.sqrt(((p - previous) ** 2).sum(axis=1)).max()) / dt
                if speed > limit:
                    failure = "a vertex moved at %.1f m/s (limit %.1f m/s)" % (speed, limit)
            if failure:
                result["failure"] = {"frame": i, "reason": failure}
                break
            out.write(p.astype("<f4").tobytes())
            previous = p
            result["frames_done"] = i + 1
            sys.stdout.write("frame %d\n" % i)
            sys.stdout.flush()
    result["seconds"] = time.time() - started
    with open(os.path.join(job_dir, "result.json"), "w") as f:
        json.dump(result, f)


try:
    main()
except BaseException:
    import traceback
    traceback.print_exc()
    sys.stderr.flush()
    os._exit(3)
sys.stdout.flush()
os._exit(0)
