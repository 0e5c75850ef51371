"""Run with a Python that has the ``bpy`` wheel: import a GLB with Blender's own glTF importer and write
the world positions of every bone's head (= joint) at every frame, in glTF axes (+Y up) [m].

    python blender_joints.py IN.glb FPS OUT.json
"""
import json
import sys

import bpy


def _fcurves(action):
    """The action's F-curves (Blender 4.4+ keeps them in layered channelbags)."""
    if hasattr(action, "fcurves") and len(action.fcurves):
        return list(action.fcurves)
    out = []
    for layer in getattr(action, "layers", ()):
        for strip in layer.strips:
            for bag in strip.channelbags:
                out += list(bag.fcurves)
    return out


path, fps, out = sys.argv[1], float(sys.argv[2]), sys.argv[3]
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.fps = int(round(fps))  # the scene runs at the file's rate (fps / fps_base)
scene.render.fps_base = scene.render.fps / fps
bpy.ops.import_scene.gltf(filepath=path)
arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
action = arm.animation_data.action
# evaluate at the keyframes themselves (the file's sample times): a rate that is not a whole number of
# frames per second puts them a little off Blender's whole frames
keys = sorted({round(k.co[0], 6) for fc in _fcurves(action) for k in fc.keyframe_points})
frames = []
for x in keys:
    scene.frame_set(int(x // 1), subframe=x - x // 1)
    mw = arm.matrix_world
    # Blender is +Z up: glTF (x, y, z) = Blender (x, z, -y)
    frames.append({b.name: [(mw @ b.head)[0], (mw @ b.head)[2], -(mw @ b.head)[1]] for b in arm.pose.bones})
first = keys[0]
json.dump({"first": first, "frames": frames}, open(out, "w"))
