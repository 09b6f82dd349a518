# garmentbake bench bake: Blender's glTF exporter on the same asset as our bake. Imports the
# glb our bake wrote (Blender's own importer: mesh, skin, shape keys, both animations), then
# times bpy.ops.export_scene.gltf writing it back as a glb with its skin, shape keys and
# animations; prints one JSON line. Usage: blender -b --factory-startup --python THIS -- IN OUT
import json
import sys
import time

import bpy
# Blender 3.4's glTF add-on still uses numpy.bool (removed in numpy 1.24), as
# tools/blender/eval_gltf.py notes.
import numpy

numpy.bool = bool

argv = sys.argv[sys.argv.index("--") + 1:]
source, target = argv[0], argv[1]
bpy.ops.wm.read_factory_settings(use_empty=True)
clock = time.perf_counter()
bpy.ops.import_scene.gltf(filepath=source)
imported = time.perf_counter() - clock
clock = time.perf_counter()
bpy.ops.export_scene.gltf(
    filepath=target,
    export_format="GLB",
    export_skins=True,
    export_morph=True,
    export_morph_normal=True,
    export_animations=True,
)
exported = time.perf_counter() - clock
print("GB_EXPORT " + json.dumps({
    "import_s": imported,
    "export_s": exported,
    "version": bpy.app.version_string,
}))
