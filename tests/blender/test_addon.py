"""The Blender add-on with a real Blender (the ``bpy`` module, Blender 5.0), headless.

Skipped where ``bpy`` is not importable (the main test environment: bpy pins numpy 1.26); ``tools/dev/test_blender.sh``
builds a Blender environment and runs them. References come from outside the add-on: the command-line bake of
the same world-space mesh with lights the test converts by hand from Blender's documented units, Blender's own
glTF importer, and Cycles renders.
"""
from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

# Blender's user folders (where Preferences > Install from Disk puts add-ons) in a scratch place, set before bpy loads
_USER = Path(tempfile.mkdtemp(prefix="meshshade-bpy-user-"))
for _var in ("BLENDER_USER_RESOURCES", "BLENDER_USER_SCRIPTS", "BLENDER_USER_CONFIG"):
    os.environ.setdefault(_var, str(_USER / _var.lower()))

bpy = pytest.importorskip("bpy", reason="bpy (Blender 5.0 as a Python module) is not installed in this environment; "
                                         "tools/dev/test_blender.sh runs these tests in one that has it")
pytestmark = pytest.mark.blender

import meshshade.blender  # noqa: E402
from meshshade.blender import addon  # noqa: E402
from meshshade.io import write_exr  # noqa: E402

MM_PER_BU = 10.0   # the scenes use 1 Blender unit = 1 cm


@pytest.fixture
def registered():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    meshshade.blender.register()
    yield
    meshshade.blender.unregister()


def new_light(name, kind, energy, location=(0, 0, 0), rotation=(0, 0, 0), color=(1, 1, 1), **extra):
    data = bpy.data.lights.new(name, kind)
    data.energy, data.color = energy, color
    for k, v in extra.items():
        setattr(data, k, v)
    ob = bpy.data.objects.new(name, data)
    ob.location, ob.rotation_euler = location, rotation
    bpy.context.scene.collection.objects.link(ob)
    return ob


def build_scene(unit_scale=0.01):
    sc = bpy.context.scene
    sc.world = None            # no World: its light would join the lamps' (test_world_and_area_light_...)
    sc.unit_settings.scale_length = unit_scale
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3, radius=1.0, location=(0.2, -0.1, 0.3),
                                          rotation=(0.4, 0.1, 0.7), scale=(1.2, 1.0, 0.9))
    ob = bpy.context.active_object
    new_light("Sun", "SUN", 800.0, rotation=(0.5, 0.3, 0.0), color=(1.0, 0.9, 0.8))
    new_light("Lamp", "POINT", 20.0, location=(0.5, 0.2, 4.0))
    new_light("Spot", "SPOT", 50.0, location=(4.0, 0.3, 0.2), rotation=(0.0, -math.pi / 2, 0.0),
              spot_size=math.radians(40.0), spot_blend=0.3)
    bpy.context.view_layer.update()
    return ob


def attribute(me, name, width=4):
    a = me.attributes[name]
    out = np.empty(len(a.data) * width, dtype=np.float32)
    a.data.foreach_get("color" if width == 4 else "vector", out)
    return out.reshape(-1, width)


def cli_bake(tmp_path, obj_path, specs, tag, *extra):
    npz = tmp_path / f"{tag}.npz"
    cmd = [sys.executable, "-m", "meshshade.cli", "bake", str(obj_path), "--units", "mm", "--material", "marble",
           "--model", "dipole", "--transport", "direct", "--quiet", "--out", str(tmp_path / f"{tag}.ply"),
           "--npz", str(npz), *extra]
    for s in specs:
        cmd += ["--light", s]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    with np.load(npz) as z:
        return np.asarray(z["radiance"])


def cycles_scene(samples, resolution):
    """The factory scene set to render with Cycles on the CPU, linear EXR, no view transform."""
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device, sc.cycles.samples = "CPU", samples
    sc.render.resolution_x = sc.render.resolution_y = resolution
    sc.view_settings.view_transform = "Standard"
    sc.render.image_settings.file_format = "OPEN_EXR"
    return sc


def white_plane(size):
    """A plane with a white Lambertian (Diffuse BSDF) material."""
    bpy.ops.mesh.primitive_plane_add(size=size)
    plane = bpy.context.active_object
    mat = bpy.data.materials.new("white")
    nodes = mat.node_tree.nodes
    nodes.clear()
    bsdf = nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (1, 1, 1, 1)
    mat.node_tree.links.new(bsdf.outputs[0], nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    plane.data.materials.append(mat)
    return plane


def camera_above(height, ortho_scale=None):
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    if ortho_scale is not None:
        cam.data.type, cam.data.ortho_scale = "ORTHO", ortho_scale
    cam.location = (0, 0, height)
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.scene.camera = cam


def test_register_and_unregister():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    meshshade.blender.register()
    try:
        assert hasattr(bpy.types, "OBJECT_OT_meshshade_bake") and hasattr(bpy.types, "MESHSHADE_PT_panel")
        assert hasattr(bpy.ops.object, "meshshade_bake") and "meshshade" in bpy.types.Object.bl_rna.properties
        meshshade.blender.register()   # enabling twice (the package and the add-on file) replaces, never fails
    finally:
        meshshade.blender.unregister()
    assert not hasattr(bpy.types, "OBJECT_OT_meshshade_bake")
    assert "meshshade" not in bpy.types.Object.bl_rna.properties


def test_the_addon_file_installs_and_enables_from_preferences(tmp_path):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    path = tmp_path / "meshshade_addon.py"
    subprocess.run([sys.executable, "-m", "meshshade.cli", "blender", str(path), "--quiet"], check=True)
    bpy.ops.preferences.addon_install(filepath=str(path))
    bpy.ops.preferences.addon_enable(module="meshshade_addon")
    try:
        assert "meshshade_addon" in bpy.context.preferences.addons
        assert hasattr(bpy.types, "OBJECT_OT_meshshade_bake")
        prefs = bpy.context.preferences.addons["meshshade_addon"].preferences
        assert prefs.python == ""   # the preference "Python for bakes", empty: Blender's own
        assert addon.bake_python(bpy.context) == sys.executable
        prefs.python = "/no/such/python"
        ob = build_scene()
        with pytest.raises(RuntimeError, match="the Python for bakes does not exist: /no/such/python"):
            bpy.ops.object.meshshade_bake()
        assert "meshshade_radiance" not in ob.data.color_attributes
    finally:
        bpy.ops.preferences.addon_disable(module="meshshade_addon")
    assert not hasattr(bpy.types, "OBJECT_OT_meshshade_bake")


def test_bake_equals_the_cli_bake_of_the_same_scene(registered, tmp_path):
    ob = build_scene()
    result = bpy.ops.object.meshshade_bake(material="marble", model="dipole", transport="direct")
    assert result == {"FINISHED"}
    me = ob.data
    got = attribute(me, "meshshade_radiance")
    assert me.color_attributes["meshshade_radiance"].data_type == "FLOAT_COLOR"
    assert me.color_attributes["meshshade_display"].data_type == "BYTE_COLOR"
    assert me.color_attributes.active_color_name == "meshshade_display"
    np.testing.assert_array_equal(got[:, 3], 1.0)

    # the same scene by hand: world-space vertices in mm, Blender's units converted from their definitions
    M = np.array(ob.matrix_world)
    co = np.array([v.co for v in me.vertices], dtype=np.float64)
    V = (co @ M[:3, :3].T + M[:3, 3]) * MM_PER_BU
    me.calc_loop_triangles()
    F = np.array([t.vertices[:] for t in me.loop_triangles])
    obj = tmp_path / "world.obj"
    with open(obj, "w") as fh:
        fh.writelines(f"v {x!r} {y!r} {z!r}\n" for x, y, z in V)
        fh.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F)
    objs = bpy.data.objects
    sun_dir = -np.array(objs["Sun"].matrix_world)[:3, 2]
    lamp = np.array(objs["Lamp"].matrix_world)[:3, 3] * MM_PER_BU
    spot_m = np.array(objs["Spot"].matrix_world)
    spot_pos, spot_axis = spot_m[:3, 3] * MM_PER_BU, -spot_m[:3, 2]
    vec = lambda v: ",".join(repr(float(x)) for x in v)   # noqa: E731
    sun = cli_bake(tmp_path, obj, [f"directional:{vec(sun_dir)}:{800 * 1e-6!r}"], "sun")   # W/m^2 -> W/mm^2
    white = cli_bake(tmp_path, obj, [f"point:{vec(lamp)}:{20 / (4 * math.pi)!r}",       # W -> W/sr
                                     f"spot:{vec(spot_pos)}:{vec(spot_axis)}:{50 / (4 * math.pi)!r}:40:0.3"], "white")
    expected = np.array([1.0, 0.9, 0.8]) * sun + white
    assert np.all(sun.max(axis=0) > 0) and np.all(white.max(axis=0) > 0)
    np.testing.assert_allclose(got[:, :3], expected.astype(np.float32), rtol=2e-7, atol=1e-7 * expected.max())


def test_errors_are_reports_not_tracebacks(registered):
    bpy.context.scene.world = None
    bpy.context.scene.unit_settings.scale_length = 0.01
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=2, radius=1.0)
    ob = bpy.context.active_object
    with pytest.raises(RuntimeError) as info:      # bpy turns an operator's ERROR report into a RuntimeError
        bpy.ops.object.meshshade_bake()
    assert "no sun, point, spot or area light" in str(info.value) and "Traceback" not in str(info.value)
    new_light("Area", "AREA", 0.0, location=(0, 0, 5))
    with pytest.raises(RuntimeError, match=r"no sun, point, spot or area light .*area 'Area'"):
        bpy.ops.object.meshshade_bake()
    new_light("Sun", "SUN", 1000.0)
    bpy.ops.object.mode_set(mode="EDIT")
    with pytest.raises(RuntimeError, match="switch to Object Mode"):
        bpy.ops.object.meshshade_bake()
    bpy.ops.object.mode_set(mode="OBJECT")
    with pytest.raises(RuntimeError, match=r"the bake failed \(exit 2\): sigma_s_prime must be finite and > 0"):
        bpy.ops.object.meshshade_bake(material="CUSTOM", sigma_s_prime=(0.0, 0.0, 0.0), sigma_a=(0.0, 0.0, 0.0))
    assert "meshshade_radiance" not in ob.data.color_attributes
    bpy.ops.object.select_all(action="DESELECT")
    bpy.context.view_layer.objects.active = bpy.data.objects["Sun"]
    assert not bpy.ops.object.meshshade_bake.poll()


def test_the_display_material_renders_the_exitance_on_cycles_scale(registered, tmp_path):
    """Cycles: an emission of strength E renders as E, a white Lambertian plane under a sun of strength S as S/π;
    so the material's exitance M W/mm² must render as M 1e6/π (addon.EMISSION_PER_W_PER_MM2)."""
    sc = cycles_scene(64, 8)
    plane = white_plane(100)
    new_light("Sun", "SUN", 2.0, angle=0.0)
    camera_above(10)

    def render():
        sc.render.filepath = str(tmp_path / "r.exr")
        bpy.ops.render.render(write_still=True)
        img = bpy.data.images.load(str(tmp_path / "r.exr"), check_existing=False)
        px = np.array(img.pixels[:]).reshape(-1, 4)
        bpy.data.images.remove(img)
        return px[:, :3].mean(axis=0)

    # rtol: Cycles' sampling noise on 64 pixels (about 1 %); what is checked is the factor pi (or its absence)
    np.testing.assert_allclose(render(), 2.0 / math.pi, rtol=0.03)   # no world light: factory scene, use_empty

    M = 3e-6   # W/mm^2 everywhere on the plane
    addon.apply_result(plane, np.full((len(plane.data.vertices), 3), M), make_material=True)
    assert plane.active_material.name == addon.MATERIAL_NAME
    np.testing.assert_allclose(render(), M * 1e6 / math.pi, rtol=0.03)


def test_glb_of_the_cli_reads_back_in_blenders_gltf_importer(registered, tmp_path):
    from scipy.spatial import cKDTree

    from meshshade.geometry.procedural import icosphere
    from meshshade.io import write_obj

    V, F = icosphere(10.0, 3)
    obj = write_obj(tmp_path / "s.obj", V, F)
    radiance = cli_bake(tmp_path, obj, ["directional:0.2,0.1,-1:1e-3"], "g")
    glb = tmp_path / "s.glb"
    subprocess.run([sys.executable, "-m", "meshshade.cli", "bake", str(obj), "--units", "mm", "--material", "marble",
                    "--model", "dipole", "--transport", "direct", "--light", "directional:0.2,0.1,-1:1e-3", "--quiet",
                    "--out", str(glb)], check=True)
    assert bpy.ops.import_scene.gltf(filepath=str(glb)) == {"FINISHED"}
    ob = next(o for o in bpy.context.scene.objects if o.type == "MESH")
    me = ob.data
    assert len(me.vertices) == V.shape[0] and len(me.polygons) == F.shape[0]
    pos = np.array([ob.matrix_world @ v.co for v in me.vertices]) * 1000.0   # glTF metres -> mm
    pos = pos[:, [0, 2, 1]] * [1.0, 1.0, -1.0]   # the importer turns glTF's +Y up into Blender's +Z up
    dist, idx = cKDTree(V).query(pos)
    assert dist.max() < 1e-3
    assert me.attributes["_RADIANCE"].data_type == "FLOAT_VECTOR"
    got = attribute(me, "_RADIANCE", width=3)
    np.testing.assert_allclose(got, radiance[idx].astype(np.float32), rtol=1e-6, atol=1e-9)
    colour = me.color_attributes[0]   # COLOR_0, as the importer names it
    assert colour.domain in ("POINT", "CORNER") and len(colour.data) > 0


def test_spot_falloff_and_point_watts_are_cycles_own(registered, tmp_path):
    """A Cycles render of a white Lambertian plane under a Blender spot (1000 W, 60 deg cone, blend 0.5, 10 units
    above) against the add-on's reading of it: radiance = P/(4π) f(θ) cos θ / d² / π with meshshade's
    Spot.falloff. This checks the P/(4π) W/sr of a point light and the smoothstep edge against Blender itself."""
    from meshshade.light.sources import Spot

    sc = cycles_scene(32, 64)
    white_plane(40)
    new_light("Spot", "SPOT", 1000.0, location=(0, 0, 10), spot_size=math.radians(60.0), spot_blend=0.5,
              shadow_soft_size=0.0)
    camera_above(20, ortho_scale=16.0)
    sc.render.filepath = str(tmp_path / "spot.exr")
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(str(tmp_path / "spot.exr"))
    px = np.array(img.pixels[:]).reshape(64, 64, 4)[:, :, 0]
    xs = (np.arange(64) + 0.5) / 64 * 16.0 - 8.0
    r = np.hypot(*np.meshgrid(xs, xs))
    d = np.hypot(r, 10.0)
    cos = 10.0 / d
    light = addon.convert_lights(addon.scene_lights(bpy.context), 1.0)[0][0][0]
    assert light.spot is not None and light.intensity == pytest.approx(1000.0 / (4 * math.pi))
    f = Spot((0, 0, -1), math.radians(60.0), 0.5).falloff(cos)
    expected = light.intensity * f * cos / d ** 2 / math.pi
    for ring in (0.5, 2.0, 3.0, 4.0, 4.5, 5.0):   # the blend zone is r = 3.9 to 5.8
        sel = np.abs(r - ring) < 0.2
        assert px[sel].mean() == pytest.approx(expected[sel].mean(), rel=0.02), ring
    assert np.all(px[r > 6.2] < 1e-3 * px.max())   # outside the cone


def test_texture_bake_equals_the_cli_texture_of_the_same_scene(registered, tmp_path):
    """Issue 31: the add-on's image of the active UV map is the CLI's ``--texture`` of the same world-space mesh
    and UV map (float precision), rows in Blender's order (bottom first)."""
    from meshshade.io import read_exr, write_obj

    bpy.context.scene.unit_settings.scale_length = 0.01
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3, radius=1.0, location=(0.2, -0.1, 0.3),
                                          rotation=(0.4, 0.1, 0.7))
    ob = bpy.context.active_object
    sun = new_light("Sun", "SUN", 800.0, rotation=(0.5, 0.3, 0.0), color=(1.0, 0.9, 0.8))
    bpy.context.view_layer.update()
    assert bpy.ops.object.meshshade_bake(material="skin1", texture=True, texture_size=64,
                                         make_material=True) == {"FINISHED"}
    img = bpy.data.images[f"meshshade {ob.name}"]
    assert tuple(img.size) == (64, 64) and img.is_float
    got = np.array(img.pixels[:], dtype=np.float32).reshape(64, 64, 4)[::-1]      # row 0: the top
    nodes = ob.active_material.node_tree.nodes
    assert any(n.type == "TEX_IMAGE" and n.image == img for n in nodes)

    # the same bake by hand: world-space mesh in mm with the active UV map per triangle corner
    me = ob.data
    M = np.array(ob.matrix_world)
    co = np.array([v.co for v in me.vertices], dtype=np.float64)
    V = (co @ M[:3, :3].T + M[:3, 3]) * MM_PER_BU
    me.calc_loop_triangles()
    F = np.array([t.vertices[:] for t in me.loop_triangles])
    uv = np.array([[me.uv_layers.active.data[k].uv[:] for k in t.loops] for t in me.loop_triangles])
    obj = write_obj(tmp_path / "world.obj", V, F, uv=uv)
    sun_dir = -np.array(sun.matrix_world)[:3, 2]
    exr = tmp_path / "cli.exr"
    subprocess.run([sys.executable, "-m", "meshshade.cli", "bake", str(obj), "--units", "mm", "--material", "skin1",
                    "--light", f"directional:{','.join(repr(float(x)) for x in sun_dir)}:{800 * 1e-6!r}",
                    "--quiet", "--texture", str(exr), "--texture-size", "64"], check=True)
    cli_px, _ = read_exr(exr)
    expected = cli_px[..., :3] * np.array([1.0, 0.9, 0.8], dtype=np.float32)
    assert expected.max() > 0
    np.testing.assert_allclose(got[..., :3], expected, rtol=2e-6, atol=1e-6 * expected.max())
    np.testing.assert_array_equal(got[..., 3], cli_px[..., 3])


def test_glb_with_a_texture_imports_with_the_texture_bound_as_emission(registered, tmp_path):
    """In a fresh Blender per hash seed: the importer walks custom attributes in a set's order, so a file that
    trips it (two custom attributes of different widths did) fails for some seeds only."""
    from meshshade.geometry.procedural import icosphere, spherical_uv
    from meshshade.io import write_obj

    V, F = icosphere(10.0, 2)
    obj = write_obj(tmp_path / "s.obj", V, F, uv=spherical_uv(V, F))
    glb = tmp_path / "s.glb"
    subprocess.run([sys.executable, "-m", "meshshade.cli", "bake", str(obj), "--units", "mm", "--material", "skin1",
                    "--light", "directional:0.2,0.1,-1:1e-3", "--quiet", "--texture", str(tmp_path / "s.exr"),
                    "--texture-size", "32", "--out", str(glb)], check=True)
    check = (
        "import sys, bpy\n"
        "bpy.ops.wm.read_factory_settings(use_empty=True)\n"
        f"assert bpy.ops.import_scene.gltf(filepath={str(glb)!r}) == {{'FINISHED'}}\n"
        "ob = next(o for o in bpy.context.scene.objects if o.type == 'MESH')\n"
        "assert len(ob.data.uv_layers) == 1\n"
        "bsdf = next(n for n in ob.active_material.node_tree.nodes if n.type == 'BSDF_PRINCIPLED')\n"
        "e = bsdf.inputs['Emission Color']\n"
        "assert e.is_linked and e.links[0].from_node.type == 'TEX_IMAGE'\n"
        "assert tuple(e.links[0].from_node.image.size) == (32, 32)\n"
        "print('imported')\n")
    for seed in range(6):
        out = subprocess.run([sys.executable, "-c", check], capture_output=True, text=True,
                             env=dict(os.environ, PYTHONHASHSEED=str(seed)))
        assert out.returncode == 0 and "imported" in out.stdout, (seed, out.stderr[-800:])


def test_world_and_area_light_bake_equals_the_cli_bake_with_the_same_exr(registered, tmp_path):
    """Issue 43: a scene lit by its World (an Environment Texture of an EXR through a Mapping node rotated about Z,
    strength 2) and an area light bakes as ``meshshade bake --light env:FILE:2e-6:ROT:z --light area:...`` of the
    same world-space mesh (Blender's W/(m^2 sr) -> W/(mm^2 sr); the add-on's meshes are Blender's world, Z up)."""
    ob = build_scene()
    for name in ("Sun", "Lamp", "Spot"):
        bpy.data.objects.remove(bpy.data.objects[name])
    exr = tmp_path / "sky.exr"
    img = np.full((32, 64, 3), 0.3, np.float32)
    img[6:9, 10:14] = 50.0
    write_exr(exr, img)
    world = bpy.data.worlds.new("W")
    if hasattr(world, "use_nodes"):
        world.use_nodes = True
    nt = world.node_tree
    bg = next(n for n in nt.nodes if n.type == "BACKGROUND")
    tex = nt.nodes.new("ShaderNodeTexEnvironment")
    tex.image = bpy.data.images.load(str(exr))
    mapping = nt.nodes.new("ShaderNodeMapping")
    mapping.vector_type = "POINT"
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(30.0))
    nt.links.new(nt.nodes.new("ShaderNodeTexCoord").outputs["Generated"], mapping.inputs["Vector"])
    nt.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    nt.links.new(tex.outputs["Color"], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = 2.0
    bpy.context.scene.world = world
    area = new_light("Box", "AREA", 30.0, location=(0.3, -0.2, 4.0), rotation=(0.2, -0.1, 0.4),
                     shape="RECTANGLE", size=0.8, size_y=0.4)
    bpy.context.view_layer.update()
    assert bpy.ops.object.meshshade_bake(material="marble", model="dipole", transport="direct") == {"FINISHED"}
    got = attribute(ob.data, "meshshade_radiance")

    M = np.array(ob.matrix_world)
    co = np.array([v.co for v in ob.data.vertices], dtype=np.float64)
    V = (co @ M[:3, :3].T + M[:3, 3]) * MM_PER_BU
    ob.data.calc_loop_triangles()
    F = np.array([t.vertices[:] for t in ob.data.loop_triangles])
    obj = tmp_path / "world.obj"
    with open(obj, "w") as fh:
        fh.writelines(f"v {x!r} {y!r} {z!r}\n" for x, y, z in V)
        fh.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F)
    A = np.array(area.matrix_world)
    vec = lambda v: ",".join(repr(float(x)) for x in v)   # noqa: E731
    rotation = math.degrees(float(mapping.inputs["Rotation"].default_value[2]))
    normal = -A[:3, 2] / np.linalg.norm(A[:3, 2])
    up = A[:3, 1] / np.linalg.norm(A[:3, 1])
    size = (float(area.data.size) * MM_PER_BU, float(area.data.size_y) * MM_PER_BU)
    specs = [f"env:{exr}:{2.0 * 1e-6!r}:{rotation!r}:z",
             f"area:{vec(A[:3, 3] * MM_PER_BU)}:{vec(normal)}:rect:{vec(size)}:{30.0!r}:{vec(up)}"]
    expected = cli_bake(tmp_path, obj, specs, "sky")
    assert np.all(expected.max(axis=0) > 0)
    np.testing.assert_allclose(got[:, :3], expected.astype(np.float32), rtol=2e-7, atol=1e-7 * expected.max())


def test_spot_textured_from_its_material_bakes_as_the_cli(registered, tmp_path, shared_meshes):
    """Issue 49: spot_textured imported by Blender's OBJ importer (its MTL's map_Kd becomes the Principled BSDF's Base
    Color image), baked "From the object's material", equals the command-line bake of the same world-space mesh
    and UVs with --albedo-map of that image and the mean free path the test converts by hand (radius x scale x mm
    per unit = 1/sigma_t', docs/blender.md)."""
    from meshshade.materials import Material

    ob = _spot_in_the_sun(shared_meshes)
    mat = ob.material_slots[0].material
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    image = bsdf.inputs["Base Color"].links[0].from_node.image
    skin = Material.preset("skin1")
    bsdf.inputs["Subsurface Weight"].default_value = 1.0
    bsdf.inputs["Subsurface Scale"].default_value = 0.5
    bsdf.inputs["Subsurface Radius"].default_value = tuple(2.0 / skin.sigma_t_prime)   # x 0.5 x 1 mm: 1/sigma_t'
    bsdf.inputs["IOR"].default_value = 1.3
    assert bpy.ops.object.meshshade_bake(material="MATERIAL") == {"FINISHED"}
    got = attribute(ob.data, "meshshade_radiance")[:, :3]

    mm_per_unit = 1000.0 * bpy.context.scene.unit_settings.scale_length     # 0.001 as Blender's float32
    ell = np.array(bsdf.inputs["Subsurface Radius"].default_value) * 0.5 * mm_per_unit   # Blender's float32 values
    path = bpy.path.abspath(image.filepath, library=image.library)
    expected = _painted_cli_bake(tmp_path, ob, 1.0 / ell, "--albedo-map", path, "--albedo-clamp")
    assert expected.max() > 0 and len(np.unique(np.round(got[:, 0] / got[:, 0].max(), 3))) > 50   # painted, lit
    np.testing.assert_allclose(got, expected.astype(np.float32), rtol=2e-7, atol=1e-7 * expected.max())


def test_spot_textured_with_a_radius_image_bakes_as_the_cli(registered, tmp_path, shared_meshes):
    """Issue 49: spot_textured with an Image Texture (Non-Color) feeding the Principled BSDF's Subsurface Radius
    besides its map_Kd on the Base Color, baked "From the object's material", equals the command-line bake with
    --albedo-map of its map_Kd and --radius-map of that image, the base's mean free path 1 x Scale x mm per unit
    (the image takes the radius's place, as in Cycles)."""
    ob = _spot_in_the_sun(shared_meshes)
    yy, xx = np.mgrid[0:32, 0:64]
    radius = (0.5 + xx / 63.0)[..., None] * np.array([1.6, 1.0, 0.7])          # mm at a scale of 1 mm per unit
    radius_path = tmp_path / "radius.exr"
    write_exr(radius_path, radius.astype(np.float32))
    mat = ob.material_slots[0].material
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(str(radius_path))
    tex.image.colorspace_settings.name = "Non-Color"
    mat.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Subsurface Radius"])
    bsdf.inputs["Subsurface Weight"].default_value = 1.0
    bsdf.inputs["Subsurface Scale"].default_value = 0.8
    bsdf.inputs["IOR"].default_value = 1.3
    assert bpy.ops.object.meshshade_bake(material="MATERIAL") == {"FINISHED"}
    got = attribute(ob.data, "meshshade_radiance")[:, :3]
    image = bsdf.inputs["Base Color"].links[0].from_node.image
    mm_per_unit = 1000.0 * bpy.context.scene.unit_settings.scale_length
    ell = np.full(3, bsdf.inputs["Subsurface Scale"].default_value) * mm_per_unit          # the radius 1: the image's
    expected = _painted_cli_bake(tmp_path, ob, 1.0 / ell, "--albedo-map",
                                 bpy.path.abspath(image.filepath, library=image.library), "--albedo-clamp",
                                 "--radius-map", str(radius_path))
    assert expected.max() > 0
    np.testing.assert_allclose(got, expected.astype(np.float32), rtol=2e-7, atol=1e-7 * expected.max())


def _spot_in_the_sun(shared_meshes):
    """spot_textured imported by Blender's OBJ importer at 40 units (1 unit = 1 mm, no World) under a sun: the
    object."""
    bpy.context.scene.world = None
    bpy.context.scene.unit_settings.scale_length = 0.001               # 1 unit = 1 mm
    bpy.ops.wm.obj_import(filepath=str(shared_meshes / "spot_textured.obj"))
    ob = bpy.context.selected_objects[0]
    bpy.context.view_layer.objects.active = ob
    ob.scale = (40.0, 40.0, 40.0)
    new_light("Sun", "SUN", 1000.0, rotation=(0.6, 0.2, 0.3))
    bpy.context.view_layer.update()
    return ob


def _painted_cli_bake(tmp_path, ob, st, *paint):
    """The command-line bake of ``ob``'s world-space mesh and UVs (written here as an OBJ in mm) under the scene's
    "Sun", in the medium of sigma_t' ``st`` and albedo 1/2 painted by ``paint`` (the CLI's options)."""
    me = ob.data
    M = np.array(ob.matrix_world)
    co = np.array([v.co for v in me.vertices], dtype=np.float64)
    mm_per_unit = 1000.0 * bpy.context.scene.unit_settings.scale_length     # 0.001 as Blender's float32
    V = (co @ M[:3, :3].T + M[:3, 3]) * mm_per_unit
    me.calc_loop_triangles()
    F = np.array([t.vertices[:] for t in me.loop_triangles])
    loops = np.array([t.loops[:] for t in me.loop_triangles])
    uv = np.array([d.uv[:] for d in me.uv_layers.active.data])[loops]
    obj = tmp_path / "world.obj"
    with open(obj, "w") as fh:
        fh.writelines(f"v {x!r} {y!r} {z!r}\n" for x, y, z in V)
        fh.writelines(f"vt {u!r} {v!r}\n" for u, v in uv.reshape(-1, 2))
        fh.writelines(f"f {a + 1}/{3 * i + 1} {b + 1}/{3 * i + 2} {c + 1}/{3 * i + 3}\n"
                      for i, (a, b, c) in enumerate(F))
    sun_dir = -np.array(bpy.data.objects["Sun"].matrix_world)[:3, 2]
    vec = lambda v: ",".join(repr(float(x)) for x in v)   # noqa: E731
    cmd = [sys.executable, "-m", "meshshade.cli", "bake", str(obj), "--units", "mm", "--sigma-s-prime",
           vec(0.5 * st), "--sigma-a", vec(0.5 * st), "--eta", "1.3", *paint, "--quiet",
           "--out", str(tmp_path / "cli.ply"), "--npz", str(tmp_path / "cli.npz"),
           "--light", f"directional:{vec(sun_dir)}:{1000 * 1e-6!r}"]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    with np.load(tmp_path / "cli.npz") as z:
        return np.asarray(z["radiance"])


def principled(name, colour, radius, scale=1.0, ior=1.3):
    """A material with a Principled BSDF: Base Color ``colour``, Subsurface Weight 1, ``radius`` x ``scale``."""
    mat = bpy.data.materials.new(name)
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
    bsdf.inputs["Subsurface Weight"].default_value = 1.0
    bsdf.inputs["Subsurface Radius"].default_value = radius
    bsdf.inputs["Subsurface Scale"].default_value = scale
    bsdf.inputs["IOR"].default_value = ior
    return mat


def test_slots_of_different_media_bake_as_the_cli_parts(registered, tmp_path):
    """Issue 49: an object whose faces use two materials of different media, baked "From the object's material",
    equals the command-line bake of the same world-space mesh with its faces in two usemtl parts, the first slot's
    medium for the rest and the second's for its part, each given the coefficients the test converts by hand
    (radius x scale x mm per unit = 1/sigma_t'; the albedo from the Base Color by the model's own reflectance,
    eq. (106)); an image on one of them is refused in one line."""
    from meshshade.kernels.painted_reflectance import albedo_for_reflectance

    sc = bpy.context.scene
    sc.world = None
    sc.unit_settings.scale_length = 0.001                                   # 1 unit = 1 mm
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3, radius=10.0)
    ob = bpy.context.active_object
    new_light("Sun", "SUN", 1000.0, rotation=(0.6, 0.2, 0.3))
    skin = principled("skin", (0.6, 0.35, 0.25), (1.2, 0.6, 0.3))
    stone = principled("stone", (0.8, 0.8, 0.75), (4.0, 3.5, 3.0))
    ob.data.materials.append(skin)
    ob.data.materials.append(stone)
    for poly in ob.data.polygons:
        poly.material_index = 1 if poly.center[0] < -2.0 else 0
    bpy.context.view_layer.update()
    assert bpy.ops.object.meshshade_bake(material="MATERIAL") == {"FINISHED"}
    got = attribute(ob.data, "meshshade_radiance")[:, :3]

    me = ob.data
    M = np.array(ob.matrix_world)
    co = np.array([v.co for v in me.vertices], dtype=np.float64)
    mm_per_unit = 1000.0 * sc.unit_settings.scale_length
    V = (co @ M[:3, :3].T + M[:3, 3]) * mm_per_unit
    me.calc_loop_triangles()
    F = np.array([t.vertices[:] for t in me.loop_triangles])
    slot = np.array([t.material_index for t in me.loop_triangles])
    obj = tmp_path / "world.obj"
    with open(obj, "w") as fh:
        fh.writelines(f"v {x!r} {y!r} {z!r}\n" for x, y, z in V)
        for i, (a, b, c) in enumerate(F):
            if i == 0 or slot[i] != slot[i - 1]:
                fh.write(f"usemtl {'stone' if slot[i] else 'skin'}\n")
            fh.write(f"f {a + 1} {b + 1} {c + 1}\n")
    vec = lambda v: ",".join(repr(float(x)) for x in v)   # noqa: E731

    def coefficients(mat):
        bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
        st = 1.0 / (np.array(bsdf.inputs["Subsurface Radius"].default_value, dtype=np.float64) * mm_per_unit)
        alb = albedo_for_reflectance(np.array(bsdf.inputs["Base Color"].default_value[:3], dtype=np.float64), 1.3)
        return vec(alb * st), vec((1 - alb) * st)

    sun_dir = -np.array(bpy.data.objects["Sun"].matrix_world)[:3, 2]
    cmd = [sys.executable, "-m", "meshshade.cli", "bake", str(obj), "--units", "mm",
           "--sigma-s-prime", coefficients(skin)[0], "--sigma-a", coefficients(skin)[1],     # the first slot: the rest
           "--material", "stone=" + "/".join(coefficients(stone)), "--eta", "1.3",
           "--quiet", "--out", str(tmp_path / "cli.ply"), "--npz", str(tmp_path / "cli.npz"),
           "--light", f"directional:{vec(sun_dir)}:{1000 * 1e-6!r}"]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    with np.load(tmp_path / "cli.npz") as z:
        expected = np.asarray(z["radiance"])
    assert expected.max() > 0
    np.testing.assert_allclose(got, expected.astype(np.float32), rtol=2e-6, atol=1e-6 * expected.max())
    # not the bake of either medium alone
    stone.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.6, 0.35, 0.25, 1.0)
    stone.node_tree.nodes["Principled BSDF"].inputs["Subsurface Radius"].default_value = (1.2, 0.6, 0.3)
    assert bpy.ops.object.meshshade_bake(material="MATERIAL") == {"FINISHED"}
    alone = attribute(ob.data, "meshshade_radiance")[:, :3]
    assert np.abs(alone - got).max() > 0.05 * got.max()
    # an image on one of several media: one line, nothing baked
    img = bpy.data.images.new("paint", 4, 4)
    img.filepath_raw = str(tmp_path / "paint.png")
    img.file_format = "PNG"
    img.save()
    tex = stone.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = img
    stone.node_tree.nodes["Principled BSDF"].inputs["Subsurface Radius"].default_value = (4.0, 3.5, 3.0)
    stone.node_tree.links.new(tex.outputs["Color"], stone.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    with pytest.raises(RuntimeError, match="painted by an image"):
        bpy.ops.object.meshshade_bake(material="MATERIAL")
