"""Run inside Blender (``blender -b --factory-startup --python tests/blender_bvh.py -- IN.bvh OUT.json [EXPORT.bvh]``).

Imports ``IN.bvh`` with Blender's own BVH importer (no axis conversion, scale 1), writes to ``OUT.json`` the
joint names (``names``) and the world position of every bone head for every frame (``heads``, T × J × 3),
and, when ``EXPORT.bvh`` is given, exports the imported armature again with Blender's BVH exporter
(6 channels on every joint, as Blender writes them). Used by tests/test_bvh_blender.py.

Blender 3.4's importer opens files with mode ``'rU'``, which Python 3.11 rejects: ``builtins.open`` is
wrapped to drop the ``U``.
"""
import builtins
import sys

import json

import bpy

_open = builtins.open


def _open_without_u(file, mode="r", *args, **kwargs):
    if isinstance(mode, str) and "U" in mode:
        mode = mode.replace("U", "") or "r"
    return _open(file, mode, *args, **kwargs)


builtins.open = _open_without_u

argv = sys.argv[sys.argv.index("--") + 1:]
src, out = argv[0], argv[1]
export = argv[2] if len(argv) > 2 else None

bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_anim.bvh(filepath=src, axis_forward="Y", axis_up="Z", global_scale=1.0, frame_start=1,
                        use_fps_scale=False, update_scene_fps=True, update_scene_duration=True,
                        rotate_mode="NATIVE")
arm = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
names = [b.name for b in arm.pose.bones]
scene = bpy.context.scene
first, last = (int(round(v)) for v in arm.animation_data.action.frame_range)  # the file's frames only
heads = []
for frame in range(first, last + 1):
    scene.frame_set(frame)
    heads.append([list(arm.matrix_world @ b.head) for b in arm.pose.bones])
with _open(out, "w") as f:
    json.dump({"names": names, "heads": heads}, f)
if export:
    bpy.context.view_layer.objects.active = arm
    arm.select_set(True)
    bpy.ops.export_anim.bvh(filepath=export, frame_start=first, frame_end=last, global_scale=1.0,
                            rotate_mode="NATIVE", root_transform_only=False)
print("blender_bvh: ok", len(names), "bones", len(heads), "frames")
