# Run by tests/export/blender_test inside Blender (blender --background --factory-startup
# --python blender_read_back.py -- SPEC.json RESULT.json). It does what an artist does with
# facedyn's exports and records what Blender then holds; the C++ test compares that with the
# take and the weights. Nothing here compares: Blender is the independent reader.
#
# SPEC: {"obj": path, "pc2": path, "mdd": path, "fps": float, "frames": [int, ...],
#        "rig_glb": path, "rig_times_s": [float, ...], "take_glb": path, "take_times_s": [...]}
# RESULT: {"obj_vertex_count": n,
#          "pc2": {"<frame>": [[x, y, z], ...]}, "mdd": {...}      (Blender units, as read)
#          "rig": {"shape_keys": [names], "weights": [{name: value} per time]},
#          "take": {"shape_key_count": n, "positions": [[[x, y, z], ...] per time]}}
import json
import sys

import bpy
import mathutils
import numpy

# Debian 12 pairs Blender 3.4 with NumPy 1.24, which removed the alias np.bool that Blender
# 3.4's glTF importer still uses (io_scene_gltf2/blender/imp/gltf2_blender_mesh.py, smooth
# flags); restore the alias (it always meant the builtin bool).
if not hasattr(numpy, "bool"):
    numpy.bool = bool

argv = sys.argv[sys.argv.index("--") + 1:]
spec = json.load(open(argv[0]))
result = {}


def clear_scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def evaluated_coordinates(obj):
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    coordinates = [list(v.co) for v in mesh.vertices]
    evaluated.to_mesh_clear()
    return coordinates


def only_mesh_object():
    meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    assert len(meshes) == 1, "expected one mesh object, got %d" % len(meshes)
    return meshes[0]


# 1. The OBJ topology with a Mesh Cache modifier per cache format. Axes: the OBJ is read
#    without conversion (forward +Y, up +Z), and the modifier's defaults are the same, so the
#    cache's coordinates reach the mesh as written.
for fmt in ("pc2", "mdd"):
    clear_scene()
    scene = bpy.context.scene
    scene.render.fps = int(round(spec["fps"]))
    scene.render.fps_base = scene.render.fps / spec["fps"]
    bpy.ops.wm.obj_import(filepath=spec["obj"], forward_axis="Y", up_axis="Z")
    obj = only_mesh_object()
    result["obj_vertex_count"] = len(obj.data.vertices)
    modifier = obj.modifiers.new("facedyn", "MESH_CACHE")
    modifier.cache_format = fmt.upper()
    modifier.filepath = spec[fmt]
    modifier.frame_start = 0.0
    # PC2 is looked up by frame index; MDD by the times it stores, which checks those too.
    modifier.time_mode = "FRAME" if fmt == "pc2" else "TIME"
    frames = {}
    for frame in spec["frames"]:
        scene.frame_set(frame)
        frames[str(frame)] = evaluated_coordinates(obj)
    result[fmt] = frames

# 2. The rig's .glb: shape keys and their animated values at the given times.
clear_scene()
scene = bpy.context.scene
scene.render.fps = 100  # frames of 10 ms, so the times below fall on whole frames
scene.render.fps_base = 1.0
bpy.ops.import_scene.gltf(filepath=spec["rig_glb"])
obj = only_mesh_object()
keys = obj.data.shape_keys
result["rig"] = {"shape_keys": [k.name for k in keys.key_blocks[1:]], "weights": []}
for t in spec["rig_times_s"]:
    scene.frame_set(int(round(t * scene.render.fps)))
    result["rig"]["weights"].append({k.name: k.value for k in keys.key_blocks[1:]})

# 3. The take's .glb: the mesh at the frames' times (Blender converts glTF's +Y up to +Z up
#    and keeps metres; the C++ side undoes both).
clear_scene()
scene = bpy.context.scene
scene.render.fps = 100
scene.render.fps_base = 1.0
bpy.ops.import_scene.gltf(filepath=spec["take_glb"])
obj = only_mesh_object()
result["take"] = {"shape_key_count": len(obj.data.shape_keys.key_blocks) - 1, "positions": []}
for t in spec["take_times_s"]:
    scene.frame_set(int(round(t * scene.render.fps)))
    world = obj.matrix_world
    result["take"]["positions"].append(
        [list(world @ mathutils.Vector(c)) for c in evaluated_coordinates(obj)])

json.dump(result, open(argv[1], "w"))
print("blender_read_back: wrote", argv[1])
