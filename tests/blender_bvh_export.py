"""Run with a Python that has the ``bpy`` wheel: import a BVH with Blender's own BVH importer and write it
back with Blender's BVH exporter, as a Blender user round-trips a clip (Blender's Z-up world, six channels
on every joint, its frame-time precision).

    python blender_bvh_export.py IN.bvh OUT.bvh [IMPORT_SCALE]

IMPORT_SCALE: the importer's global scale (0.056444 takes CMU units to metres). Made
``tests/fixtures/blender/09_01_blender_metres.bvh`` from ``src/froude/data/09_01.bvh`` with Blender 5.0.1
(the ``bpy`` wheel) and IMPORT_SCALE 0.056444.
"""
# ruff: noqa: I001  (Blender's addon_utils can be imported only once bpy is)
import sys

import bpy
import addon_utils

src, dst = sys.argv[1], sys.argv[2]
addon_utils.enable("io_anim_bvh")
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_anim.bvh(filepath=src, global_scale=float(sys.argv[3]) if len(sys.argv) > 3 else 1.0,
                        update_scene_fps=True, update_scene_duration=True, rotate_mode="NATIVE")
arm = bpy.context.selected_objects[0]
bpy.context.view_layer.objects.active = arm
scene = bpy.context.scene
lo, hi = arm.animation_data.action.frame_range
scene.frame_start, scene.frame_end = int(round(lo)), int(round(hi))
bpy.ops.export_anim.bvh(filepath=dst, frame_start=scene.frame_start, frame_end=scene.frame_end,
                        global_scale=1.0, rotate_mode="NATIVE", root_transform_only=False)
