"""A screenshot of a BVH file of the agent in Blender, for the docs (not part of CI).

Needs Debian's blender and xvfb. Run from the repository root:

    xvfb-run -s "-screen 0 1280x800x24" blender --python tools/blender_screenshot.py -- \
        outputs/08_your_own_voice/generated/agent.bvh docs/images/blender_bvh.png

Blender imports the file as a person would (File > Import > Motion Capture), shows frame 100 (4 s) in
the 3D view seen from the front, saves a screenshot of its window and quits.
"""

import sys

import bpy
import io_anim_bvh.import_bvh as bvh_importer

# Debian's Blender 3.4 runs on Python 3.11, which no longer accepts the "rU" mode its BVH importer
# opens files with: let the importer open them in plain "r" mode.
bvh_importer.open = lambda path, mode="r", *args, **kwargs: open(
    path, mode.replace("U", ""), *args, **kwargs
)

bvh, screenshot = sys.argv[sys.argv.index("--") + 1 :]
FRAME = 100  # 4 s in: mid-sentence in the recordings of chapter 08

bpy.context.preferences.view.show_splash = False  # the first start's welcome would hide the view

bpy.ops.object.select_all(action="SELECT")
bpy.ops.object.delete()  # the default cube, camera and light
bpy.ops.import_anim.bvh(
    filepath=bvh, global_scale=0.01, update_scene_fps=True, update_scene_duration=True
)
armature = bpy.context.selected_objects[0]
armature.data.display_type = "STICK"
bpy.context.scene.frame_set(FRAME)


def shoot():
    window = bpy.context.window_manager.windows[0]
    for area in window.screen.areas:
        if area.type == "VIEW_3D":
            region = next(r for r in area.regions if r.type == "WINDOW")
            with bpy.context.temp_override(window=window, area=area, region=region):
                bpy.ops.view3d.view_axis(type="FRONT")
                bpy.ops.view3d.view_selected()
            area.spaces.active.shading.type = "SOLID"
    bpy.app.timers.register(save, first_interval=1.0)


def save():
    window = bpy.context.window_manager.windows[0]
    with bpy.context.temp_override(window=window):
        bpy.ops.screen.screenshot(filepath=screenshot)
    bpy.ops.wm.quit_blender()


bpy.app.timers.register(shoot, first_interval=2.0)
