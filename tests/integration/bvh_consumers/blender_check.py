# blender_check.py — imports a BVH file with Blender's own BVH importer (a real consumer)
# headless and checks the armature's bone count and the action's frame range.
#   blender -b --factory-startup --python-exit-code 1 --python blender_check.py -- \
#       FILE.bvh EXPECTED_BONES EXPECTED_FRAMES
# Prints one JSON line prefixed "BLENDER_RESULT "; a failed check raises (exit 1).
import builtins
import json
import sys

import bpy

# Blender 3.4's importer opens files with mode 'rU', which Python 3.11 rejects.
_open = builtins.open


def _open_without_u(file, mode='r', *args, **kwargs):
    return _open(file, mode.replace('U', ''), *args, **kwargs)


builtins.open = _open_without_u

path, bones, frames = sys.argv[sys.argv.index('--') + 1:][:3]
result = bpy.ops.import_anim.bvh(filepath=path, update_scene_fps=False, update_scene_duration=True)
if result != {'FINISHED'}:
    raise SystemExit(f'import failed: {result}')
arm = [o for o in bpy.data.objects if o.type == 'ARMATURE']
if len(arm) != 1:
    raise SystemExit(f'expected one armature, got {len(arm)}')
obj = arm[0]
action = obj.animation_data.action if obj.animation_data else None
start, end = (action.frame_range if action else (0, 0))
out = {
    'file': path,
    'bones': len(obj.data.bones),
    'frame_start': int(start),
    'frame_end': int(end),
    'frames': int(end) - int(start) + 1,
    'root': obj.data.bones[0].name if obj.data.bones else None,
}
print('BLENDER_RESULT ' + json.dumps(out))
if out['bones'] != int(bones) or out['frames'] != int(frames):
    raise SystemExit(f'mismatch: expected {bones} bones and {frames} frames')
