"""README's Blender picture: spot (../shared/meshes/spot.obj, scaled to 50 mm) baked by the meshshade add-on in a
real Blender (the bpy module, headless) under a sun and a point light, then rendered by Cycles on the CPU with the
add-on's display material (the baked exitance as emission): meshshade's bake as Blender shows it.

Run with the Blender environment of tools/dev/test_blender.sh::

    .blender-venv/bin/python tools/docs/blender_screenshot.py [--out docs/images/blender_spot.png] [--samples 64]

Prints one JSON line (bake and render seconds, vertex count, peak exitance).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import bpy
import numpy as np

import meshshade.blender

ROOT = Path(__file__).resolve().parents[2]
SPOT = ROOT.parent / "shared" / "meshes" / "spot.obj"


def aim(ob, location, target) -> None:
    """Place ``ob`` (a camera or light: it looks along its local -Z, +Y up) at ``location`` facing ``target``."""
    ob.location = location
    d = np.array(target, dtype=float) - np.array(location, dtype=float)
    ob.rotation_euler = (math.atan2(math.hypot(d[0], d[1]), -d[2]), 0.0, math.atan2(-d[0], d[1]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "images" / "blender_spot.png"))
    ap.add_argument("--samples", type=int, default=64)
    ap.add_argument("--size-mm", type=float, default=50.0, help="largest extent of the cow [mm]")
    ap.add_argument("--material", default="skin1")
    args = ap.parse_args(argv)
    if not SPOT.exists():
        print(f"blender_screenshot: {SPOT} not found (../shared/meshes is needed)", file=sys.stderr)
        return 2

    bpy.ops.wm.read_factory_settings(use_empty=True)
    meshshade.blender.register()
    sc = bpy.context.scene
    sc.unit_settings.system, sc.unit_settings.scale_length = "METRIC", 0.001   # 1 Blender unit = 1 mm
    bpy.ops.wm.obj_import(filepath=str(SPOT))
    ob = bpy.context.selected_objects[0]
    bpy.context.view_layer.objects.active = ob
    ob.scale = [args.size_mm / max(ob.dimensions)] * 3
    bpy.context.view_layer.update()
    ob.location = -np.array(ob.matrix_world @ (sum((v.co for v in ob.data.vertices), ob.data.vertices[0].co * 0)
                                               / len(ob.data.vertices))) + np.array(ob.location)

    def light(name, kind, energy, location, target, **extra):
        data = bpy.data.lights.new(name, kind)
        data.energy = energy
        for k, v in extra.items():
            setattr(data, k, v)
        lo = bpy.data.objects.new(name, data)
        aim(lo, location, target)
        sc.collection.objects.link(lo)
        return lo

    light("Sun", "SUN", 3.0, (-80.0, 40.0, 90.0), (0.0, 0.0, 0.0))           # 3 W/m^2 (a dim sun)
    light("Lamp", "POINT", 0.05, (45.0, -45.0, 15.0), (0.0, 0.0, 0.0))        # 50 mW behind, 65 mm away
    bpy.context.view_layer.update()

    t0 = time.perf_counter()
    result = bpy.ops.object.meshshade_bake(material=args.material, model="auto", make_material=True)
    t_bake = time.perf_counter() - t0
    if result != {"FINISHED"}:
        print("blender_screenshot: the bake did not finish", file=sys.stderr)
        return 1

    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    aim(cam, (-130.0, 105.0, 45.0), (0.0, 0.0, 0.0))
    cam.data.lens, cam.data.clip_start, cam.data.clip_end = 60.0, 1.0, 10000.0
    sc.camera = cam
    sc.world = bpy.data.worlds.new("World")
    bg = sc.world.node_tree.nodes.get("Background")
    bg.inputs["Color"].default_value = (0.02, 0.02, 0.025, 1.0)
    sc.render.engine = "CYCLES"
    sc.cycles.device, sc.cycles.samples = "CPU", args.samples
    sc.render.resolution_x, sc.render.resolution_y = 800, 560
    sc.view_settings.view_transform = "AgX"
    sc.render.image_settings.file_format = "PNG"
    sc.render.filepath = str(Path(args.out).resolve())
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    t_render = time.perf_counter() - t0
    attr = ob.data.color_attributes["meshshade_radiance"]
    vals = np.empty(len(attr.data) * 4, dtype=np.float32)
    attr.data.foreach_get("color", vals)
    peak = vals.reshape(-1, 4)[:, :3].max(axis=0)
    print(json.dumps({"out": args.out, "vertices": len(ob.data.vertices), "size_mm": args.size_mm,
                      "material": args.material, "bake_s": round(t_bake, 1), "render_s": round(t_render, 1),
                      "samples": args.samples, "peak_exitance_w_per_mm2": [float(x) for x in peak]}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
