"""Run with a Python that has the ``bpy`` wheel and froude: the add-on's operators on clips as a Blender user
gets them (Blender's own BVH importer, optionally through Blender's FBX exporter and importer), headless.

    python blender_addon_run.py SPEC.json OUT_DIR

SPEC: {"addons_dir": the folder ``froude blender --install-addon`` wrote into (its add-on is enabled and
disabled first, result in OUT_DIR/addon.json), "cases": [{"name", "bvh", "import_scale", "fbx": bool, "glb":
bool, "ops": [[operator, {setting: value}], ...]}]}; operator is "info", "scale" or "accelerate"
(bpy.ops.froude.*), settings are scene.froude's; "disconnect" {"bones": [...]} disconnects those bones in
Edit Mode, as a user does; "panel" draws the panel into a recording layout (the controls drawn, and any
property that scene.froude lacks).
For each case OUT_DIR/NAME.json holds per operator: the result ({'FINISHED'} or the error line), the panel's
error, info and report, whether the original action is untouched (its keyframes, and the action still in
bpy.data), the actions in the file; and OUT_DIR/NAME_K.npz the world joint positions of operator K's new
action at its keys, in froude's axes (+Y up) and metres [m]: names (J,), heads (F, J, 3). With "glb", Blender's
glTF exporter writes OUT_DIR/NAME.glb from the imported armature (before any operator), with its leaf bones
(the chain ends: head top, toe and finger tips).
"""
# ruff: noqa: I001  (Blender's addon_utils can be imported only once bpy is)
import json
import os
import sys
from pathlib import Path
from types import SimpleNamespace

import bpy
import addon_utils
import numpy as np

from froude.apps.blender import addon


def _fcurves(action):
    """The action's F-curves (Blender 4.4+ keeps them in layered channelbags)."""
    if hasattr(action, "fcurves") and len(action.fcurves):
        return list(action.fcurves)
    return [fc for layer in getattr(action, "layers", ()) for strip in layer.strips
            for bag in strip.channelbags for fc in bag.fcurves]


def snapshot(action) -> dict:
    """Every key of every F-curve of an action: {data_path[index]: [(frame, value), ...]}."""
    out = {}
    for fc in _fcurves(action):
        co = np.empty(2 * len(fc.keyframe_points), np.float32)
        fc.keyframe_points.foreach_get("co", co)
        out[f"{fc.data_path}[{fc.array_index}]"] = co.tolist()
    return out


def heads(obj, names, frames) -> np.ndarray:
    """(F, J, 3) world head of each named bone at each scene frame, froude's axes (x, z, -y), metres."""
    scene = bpy.context.scene
    unit = scene.unit_settings.scale_length
    out = np.empty((len(frames), len(names), 3))
    for k, f in enumerate(frames):
        whole = int(np.floor(f + 1e-9))
        scene.frame_set(whole, subframe=float(f - whole))
        mw = obj.matrix_world
        out[k] = [tuple(mw @ obj.pose.bones[n].head) for n in names]
    return np.stack([out[..., 0], out[..., 2], -out[..., 1]], axis=-1) * unit


class Layout:
    """A stand-in for a panel's UILayout that records what is drawn: ("label" | "prop" | "operator", text)."""

    def __init__(self, controls: list):
        self.controls = controls

    def label(self, text="", **_):
        self.controls.append(("label", text))

    def prop(self, data, name, **_):
        self.controls.append(("prop", name))

    def operator(self, idname, **_):
        self.controls.append(("operator", idname))

    def column(self, **_):
        return self

    def row(self, **_):
        return self

    def box(self, **_):
        return self


def check_installed_addon(addons_dir: str) -> dict:
    """Enable the add-on that ``froude blender --install-addon`` wrote, as Blender does, then disable it."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sys.path.insert(0, addons_dir)
    import froude_blender

    froude_blender.register()
    out = {"bl_info": froude_blender.bl_info["name"], "settings": hasattr(bpy.types.Scene, "froude"),
           "operators": sorted(n for n in dir(bpy.ops.froude) if not n.startswith("_")),
           "panel": hasattr(bpy.types, "FROUDE_PT_panel")}
    froude_blender.unregister()
    out["unregistered"] = not hasattr(bpy.types.Scene, "froude") and not hasattr(bpy.types, "FROUDE_PT_panel")
    return out


def load_case(case, out_dir: Path):
    """Import the case's BVH (and round-trip it through FBX); returns the active armature."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon_utils.enable("io_anim_bvh")
    addon_utils.enable("io_scene_fbx")
    addon_utils.enable("io_scene_gltf2")
    addon.register()
    bpy.ops.import_anim.bvh(filepath=case["bvh"], global_scale=case["import_scale"], update_scene_fps=True,
                            update_scene_duration=True, rotate_mode="NATIVE")
    arm = bpy.context.selected_objects[0]
    bpy.context.view_layer.objects.active = arm
    scene = bpy.context.scene
    lo, hi = arm.animation_data.action.frame_range
    scene.frame_start, scene.frame_end = int(round(lo)), int(round(hi))
    if case.get("glb"):
        bpy.ops.export_scene.gltf(filepath=str(out_dir / f"{case['name']}.glb"), export_format="GLB",
                                  use_selection=True, export_animations=True, export_leaf_bone=True)
    if case.get("fbx"):
        fbx = out_dir / f"{case['name']}.fbx"
        # a mesh skinned to the armature, as in every character FBX: its bind pose carries the armature's rest
        # pose (an FBX of bones alone makes the pose at export time the rest pose)
        bpy.ops.mesh.primitive_cube_add(size=0.1)
        mesh = bpy.context.active_object
        mesh.select_set(True)
        arm.select_set(True)
        bpy.context.view_layer.objects.active = arm
        bpy.ops.object.parent_set(type="ARMATURE_NAME")
        # every frame baked as it is (no curve simplification); Blender's default leaf bones mark the chain
        # ends, which the importer turns back into bone tails
        bpy.ops.export_scene.fbx(filepath=str(fbx), use_selection=True, object_types={"ARMATURE", "MESH"},
                                 bake_anim=True, bake_anim_use_all_actions=False, bake_anim_use_nla_strips=False,
                                 bake_anim_simplify_factor=0.0, add_leaf_bones=True)
        fps, base = scene.render.fps, scene.render.fps_base
        for ob in list(bpy.data.objects):
            bpy.data.objects.remove(ob)
        for act in list(bpy.data.actions):
            bpy.data.actions.remove(act)
        bpy.ops.import_scene.fbx(filepath=str(fbx), ignore_leaf_bones=True, use_anim=True)
        scene.render.fps, scene.render.fps_base = fps, base
        arm = next(o for o in bpy.context.selected_objects if o.type == "ARMATURE")
        bpy.context.view_layer.objects.active = arm
    return arm


def run_case(case, out_dir: Path) -> dict:
    obj = load_case(case, out_dir)
    original = obj.animation_data.action
    before = snapshot(original)
    st = bpy.context.scene.froude
    log = {"armature": obj.name, "original": original.name, "bones": [b.name for b in obj.data.bones], "ops": []}
    for k, (op, settings) in enumerate(case["ops"]):
        for key, value in settings.items():
            if op != "disconnect":
                setattr(st, key, value)
        n_actions = len(bpy.data.actions)
        if op == "disconnect":  # what the add-on's error tells the user to do (Edit Mode, Alt+P)
            bpy.ops.object.mode_set(mode="EDIT")
            for name in settings["bones"]:
                obj.data.edit_bones[name].use_connect = False
            bpy.ops.object.mode_set(mode="OBJECT")
            log["ops"].append({"op": op, "bones": settings["bones"]})
            continue
        if op == "panel":  # the panel drawn into a layout that records every control
            controls: list = []
            addon.FROUDE_PT_panel.draw(SimpleNamespace(layout=Layout(controls)), bpy.context)
            known = set(st.bl_rna.properties.keys())
            log["ops"].append({"op": op, "controls": controls,
                               "unknown_props": [n for k, n in controls if k == "prop" and n not in known]})
            continue
        markers = sorted((m.name, m.frame) for m in bpy.context.scene.timeline_markers)
        try:
            result = sorted(getattr(bpy.ops.froude, op)())
        except RuntimeError as e:  # an operator that reports an error raises here
            result = ["ERROR: " + str(e).strip()]
        entry = {"op": op, "result": result, "error": st.error, "info": st.info_json, "report": st.report_json,
                 "actions_before": n_actions, "actions": sorted(a.name for a in bpy.data.actions),
                 "active": obj.animation_data.action.name,
                 "markers_changed": markers != sorted((m.name, m.frame) for m in bpy.context.scene.timeline_markers)}
        new = obj.animation_data.action
        if op != "info" and result == ["FINISHED"]:
            names = [b.name for b in obj.data.bones if b.name in case.get("joints", [b.name for b in obj.data.bones])]
            keys = sorted({round(p.co[0], 6) for fc in _fcurves(new) for p in fc.keyframe_points})
            np.savez(out_dir / f"{case['name']}_{k}.npz", names=np.array(names), heads=heads(obj, names, keys))
            entry["keys"] = [keys[0], keys[-1], len(keys)]
            obj.animation_data.action = original  # the next operator reads the original again
            if hasattr(obj.animation_data, "action_slot") and original.slots:
                obj.animation_data.action_slot = original.slots[0]
        entry["original_untouched"] = original.name in bpy.data.actions and snapshot(original) == before
        log["ops"].append(entry)
    return log


def main() -> None:
    spec = json.loads(Path(sys.argv[1]).read_text())
    out_dir = Path(sys.argv[2])
    if spec.get("addons_dir"):
        (out_dir / "addon.json").write_text(json.dumps(check_installed_addon(spec["addons_dir"])))
    for case in spec["cases"]:
        log = run_case(case, out_dir)
        (out_dir / f"{case['name']}.json").write_text(json.dumps(log, indent=1))


if __name__ == "__main__":
    main()
    sys.stdout.flush()
    os._exit(0)  # bpy 4.5 can hang in its own shutdown; every output is written and closed by now
