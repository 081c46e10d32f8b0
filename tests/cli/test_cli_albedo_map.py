"""`meshshade bake --albedo-map FILE|mtl|vertex` (issue 49, docs/physics.md §17): a colour map over the UVs decoded
from sRGB, the OBJ's map_Kd, a PLY's vertex colours; bad input is a clean failure (exit 2, one line, nothing
written)."""
import numpy as np
import pytest

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere, spherical_uv
from meshshade.io import load_mesh, write_obj, write_ply, write_png
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.painted import PaintedMaterial
from meshshade.transport.baking import bake

SUN = "directional:0,0,-1"


@pytest.fixture
def textured(tmp_path):
    """A 10 mm ball with a longitude-latitude UV map, a material library naming a PNG of one sRGB value 128."""
    V, F = icosphere(10.0, 2)
    write_obj(tmp_path / "ball.obj", V, F, uv=spherical_uv(V, F))
    text = (tmp_path / "ball.obj").read_text()
    (tmp_path / "ball.obj").write_text("mtllib ball.mtl\n" + text)
    (tmp_path / "ball.mtl").write_text("newmtl paint\nKd 1 1 1\nmap_Kd paint.png\n")
    write_png(tmp_path / "paint.png", np.full((8, 8, 3), 128, dtype=np.uint8))
    return tmp_path


def test_an_srgb_map_over_the_uvs_bakes_as_its_linear_colour(cli, textured):
    out = textured / "out.ply"
    rc, _, err = cli.run(["bake", textured / "ball.obj", "--material", "skin1", "--albedo-map", "mtl", "--light",
                          SUN, "--out", out, "--npz", textured / "out.npz", "--quiet"])
    assert rc == 0, err
    got = np.load(textured / "out.npz")["radiance"]
    mesh = load_mesh(textured / "ball.obj")
    linear = ((128 / 255 + 0.055) / 1.055) ** 2.4          # IEC 61966-2-1, written out here
    ref = bake(mesh, PaintedMaterial(Material.preset("skin1"), colour=np.full((mesh.n_vertices, 3), linear)),
               DirectionalLight([0, 0, -1.0], 1.0)).radiance
    np.testing.assert_allclose(got, ref, rtol=1e-5, atol=1e-6 * ref.max())


def test_a_map_file_by_name_gives_the_same(cli, textured):
    rc, _, err = cli.run(["bake", textured / "ball.obj", "--material", "skin1", "--albedo-map", textured / "paint.png",
                          "--light", SUN, "--npz", textured / "a.npz", "--out", textured / "a.ply", "--quiet"])
    assert rc == 0, err


@pytest.mark.parametrize("value, needle", [(0, "painted colour must lie in"), (255, "painted colour must lie in")])
def test_a_colour_no_medium_has_is_refused(cli, textured, value, needle):
    write_png(textured / "paint.png", np.full((8, 8, 3), value, dtype=np.uint8))
    before = cli.snapshot(textured)
    rc, _, err = cli.run(["bake", textured / "ball.obj", "--material", "skin1", "--albedo-map", "mtl", "--light", SUN,
                          "--out", textured / "out.ply"])
    cli.assert_clean_failure(rc, err, before, textured, needle)


def test_albedo_clamp_states_what_it_moved(cli, textured):
    write_png(textured / "paint.png", np.full((8, 8, 3), 255, dtype=np.uint8))
    rc, _, err = cli.run(["bake", textured / "ball.obj", "--material", "skin1", "--albedo-map", "mtl",
                          "--albedo-clamp", "--light", SUN, "--out", textured / "out.ply"])
    assert rc == 0, err
    assert "--albedo-clamp moved 192 painted values" in err


def test_unreadable_map_mesh_without_uvs_and_surface_models_are_refused(cli, textured, tmp_path):
    (textured / "bad.png").write_text("not an image")
    V, F = icosphere(10.0, 2)
    write_obj(textured / "plain.obj", V, F)
    before = cli.snapshot(textured)
    cases = [(["--albedo-map", textured / "bad.png"], "cannot read the colour map"),
             (["--albedo-map", textured / "missing.exr"], "not found"),
             (["--albedo-map", "mtl", "--model", "dipole"], "needs the volume model"),
             (["--albedo-map", "vertex"], "needs a PLY")]
    for extra, needle in cases:
        rc, _, err = cli.run(["bake", textured / "ball.obj", "--material", "skin1", *extra, "--light", SUN,
                              "--out", textured / "out.ply"])
        cli.assert_clean_failure(rc, err, before, textured, needle)
    rc, _, err = cli.run(["bake", textured / "plain.obj", "--material", "skin1", "--albedo-map",
                          textured / "paint.png", "--light", SUN, "--out", textured / "out.ply"])
    cli.assert_clean_failure(rc, err, before, textured, "UVs")
    rc, _, err = cli.run(["bake", textured / "plain.obj", "--material", "skin1", "--albedo-map", "mtl",
                          "--light", SUN, "--out", textured / "out.ply"])
    cli.assert_clean_failure(rc, err, before, textured, "mtllib")


def test_vertex_colours_of_a_ply(cli, tmp_path):
    V, F = icosphere(10.0, 2)
    colours = np.where(V[:, 2:3] > 0, [200, 120, 120], [120, 200, 120]).astype(np.uint8)
    write_ply(tmp_path / "ball.ply", V, F, vertex_colors=colours)
    rc, _, err = cli.run(["bake", tmp_path / "ball.ply", "--material", "skin1", "--albedo-map", "vertex", "--light",
                          SUN, "--npz", tmp_path / "v.npz", "--out", tmp_path / "v.ply", "--quiet"])
    assert rc == 0, err
    got = np.load(tmp_path / "v.npz")["radiance"]
    mesh = Mesh.from_arrays(np.asarray(V, dtype=np.float32).astype(np.float64), F)
    lin = np.where(colours / 255 <= 0.04045, colours / 255 / 12.92, ((colours / 255 + 0.055) / 1.055) ** 2.4)
    ref = bake(mesh, PaintedMaterial(Material.preset("skin1"), colour=lin), DirectionalLight([0, 0, -1.0], 1.0))
    np.testing.assert_allclose(got, ref.radiance, rtol=1e-5, atol=1e-6 * ref.radiance.max())
