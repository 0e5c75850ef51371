"""Run with a Python that has the ``bpy`` wheel: import a GLB with Blender's own glTF importer and write
the world positions of every bone's head (= joint) at every frame, in glTF axes (+Y up) [m].

    python blender_joints.py IN.glb FPS OUT.json
"""
import json
import sys

import bpy

path, fps, out = sys.argv[1], float(sys.argv[2]), sys.argv[3]
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.fps = int(round(fps))  # keyframes land on whole frames at the file's rate
scene.render.fps_base = scene.render.fps / fps
bpy.ops.import_scene.gltf(filepath=path)
arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
action = arm.animation_data.action
first, last = (int(round(x)) for x in action.frame_range)
frames = {}
for f in range(first, last + 1):
    scene.frame_set(f)
    mw = arm.matrix_world
    # Blender is +Z up: glTF (x, y, z) = Blender (x, z, -y)
    frames[f] = {b.name: [(mw @ b.head)[0], (mw @ b.head)[2], -(mw @ b.head)[1]] for b in arm.pose.bones}
json.dump({"first": first, "frames": [frames[f] for f in range(first, last + 1)]}, open(out, "w"))
