"""render.py and the image writers: EXR round trip, the exact profile along a beam's row, exit convention."""
import numpy as np
import pytest

from meshshade.names import DEFAULT_MODEL
from meshshade import Material, io
from meshshade.output import render
from meshshade.cli.main import main
from meshshade.errors import MeshshadeError
from meshshade.geometry import procedural
from meshshade.geometry.mesh import Mesh
from meshshade.kernels.fresnel import fresnel_transmittance_entry
from meshshade.kernels.sphere import sphere_series_profile
from meshshade.light import BeamLight, DirectionalLight
from meshshade.transport.baking import bake
from meshshade.transport import BakeOptions


def test_write_exr_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    img = rng.random((7, 9, 4)).astype(np.float32) * 1e-3
    meta = {"model": "curved", "material": "skin1", "lights": "beam", "camera": "ortho", "units": "W/(mm^2 sr)"}
    path = io.write_exr(tmp_path / "a.exr", img, meta)
    back, got = io.read_exr(path)
    np.testing.assert_array_equal(back, img)
    assert got == meta
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary left


def test_write_png_round_trip(tmp_path):
    img = np.arange(5 * 6 * 4, dtype=np.uint8).reshape(5, 6, 4)
    back, _ = io.read_exr(io.write_png(tmp_path / "a.png", img))
    np.testing.assert_array_equal(np.round(back * 255).astype(np.uint8), img)


def test_exit_normalisation_gives_back_exitance():
    """int L cos domega over the hemisphere = M."""
    x, w = np.polynomial.legendre.leggauss(200)
    mu = 0.5 * (x + 1)
    L = render.exit_radiance(np.ones((mu.size, 3)), mu, 1.3)[:, 0]
    assert np.isclose(2 * np.pi * 0.5 * np.sum(w * L * mu), 1.0, rtol=1e-10)
    assert np.isclose(render.exit_normalisation(1.0), 1.0)


@pytest.fixture(scope="module")
def sphere_bake():
    V, F = procedural.icosphere(10.0, 4)
    mesh = Mesh.from_arrays(V, F)
    mat = Material(1.0, 0.01)
    return mesh, mat, bake(mesh, mat, [BeamLight((0, 0, 30), (0, 0, -1))], BakeOptions(model="exact-sphere"))


@pytest.mark.parametrize("per_pixel, tol", [(True, 1e-2), (False, 5e-2)])
def test_render_radiance_beam_row_follows_exact_profile(sphere_bake, per_pixel, tol):
    mesh, mat, res = sphere_bake
    cam = render.Camera("orthographic", (0, 0, 40), (0, 0, 0), (0, 1, 0), ortho_height=22)
    W = 101
    ex = render.PixelGather(mesh, res) if per_pixel else None
    rgb, alpha = render.render_radiance(mesh, res.radiance, cam, W, W, 1, exitance_at=ex)
    x = (2 * (np.arange(W) + 0.5) / W - 1) * 11
    # per-vertex interpolation smears the peak over the entry fan (edge ~0.6 mm): judged beyond 2 mm there
    ok = (np.abs(x) < 9.0) & ((np.abs(x) > 2.0) | per_pixel)
    th = np.arcsin(np.abs(x[ok]) / 10)
    ch = mat.channel(1)
    st = ch["sigma_t_prime"]
    R = sphere_series_profile(th, R0_opt=10 * st, albedo_prime=ch["albedo_prime"], eta=1.3) * st * st
    M = fresnel_transmittance_entry(1.0, 1.3) * R
    L = render.exit_radiance(np.stack([M] * 3, 1), np.cos(th), 1.3)[:, 1]
    rel = rgb[W // 2, ok, 1] / L - 1
    assert np.max(np.abs(rel)) < tol, (x[ok][np.argmax(np.abs(rel))], rel[np.argmax(np.abs(rel))])
    assert np.all(alpha[W // 2, ok] == 1)


def test_auto_camera_frames_the_mesh():
    V, F = procedural.pebble(subdivisions=2)
    mesh = Mesh.from_arrays(V, F)
    for view in [(0, 0, -1), (1, 0, 0), (0, -1, 0)]:
        cam = render.auto_camera(mesh, view)
        rgb, alpha = render.render_radiance(mesh, np.ones((mesh.n_vertices, 3)), cam, 48, 48, 1)
        assert alpha.sum() > 0.1 * alpha.size
        assert alpha[0].sum() == alpha[-1].sum() == alpha[:, 0].sum() == alpha[:, -1].sum() == 0  # margin
    # up parallel to the view direction (0, 0, -1): no image plane; the package's own error, with its reason
    with pytest.raises(MeshshadeError, match=r"up vector \(0, 0, 1\) is parallel to the view direction"):
        render.Camera("orthographic", (0, 0, 1), (0, 0, 0), (0, 0, 1))


def test_cli_render(tmp_path):
    V, F = procedural.icosphere(10.0, 3)
    io.write_ply(tmp_path / "s.ply", V, F)
    rc = main(["render", str(tmp_path / "s.ply"), "--material", "skin1", "--light", "directional:0,0,-1",
               "--width", "40", "--height", "30", "--spp", "2", "--out", str(tmp_path / "img"), "-q",
               "--background", "0.1,0.1,0.1", "--tonemap", "exposure"])
    assert rc == 0
    img, meta = io.read_exr(tmp_path / "img.exr")
    assert img.shape == (30, 40, 4) and meta["model"] == DEFAULT_MODEL and "skin1" in meta["material"]
    png, _ = io.read_exr(tmp_path / "img.png")
    assert png.shape == (30, 40, 4) and np.all(png[..., 3] == 1)
    assert main(["render", str(tmp_path / "s.ply"), "--material", "skin1", "--light", "directional:0,0,-1",
                 "--camera", "bogus", "--out", str(tmp_path / "x")]) == 2


def test_pixel_gather_equals_bake_at_vertices():
    V, F = procedural.pebble(subdivisions=2)
    mesh = Mesh.from_arrays(V, F)
    res = bake(mesh, Material.preset("skin1"), [DirectionalLight((0.3, -0.5, -1))], BakeOptions(model="curved"))
    g = render.PixelGather(mesh, res)
    f = np.array([np.flatnonzero((mesh.faces == v).any(1))[0] for v in range(mesh.n_vertices)])
    bary = (mesh.faces[f] == np.arange(mesh.n_vertices)[:, None]).astype(float)
    np.testing.assert_allclose(g(mesh.vertices, f, bary), res.radiance, rtol=1e-9, atol=1e-12 * res.radiance.max())


def test_a_camera_that_sees_none_of_the_mesh_says_so(tmp_path, capsys):
    """A camera looking away from the mesh: the image is empty, and the API warns (the CLI prints one warning
    line naming the camera and the mesh's bounds, exit 0: the empty image is what was asked for)."""
    V, F = procedural.icosphere(10.0, 2)
    mesh = Mesh.from_arrays(V, F)
    away = render.Camera("perspective", eye=(0.0, 0.0, 100.0), target=(0.0, 0.0, 200.0))
    with pytest.warns(UserWarning, match="sees none of the mesh"):
        rgb, alpha = render.render_radiance(mesh, np.ones((mesh.n_vertices, 3)), away, 16, 12, 1)
    assert not alpha.any() and not rgb.any()
    io.write_ply(tmp_path / "s.ply", V, F)
    rc = main(["render", str(tmp_path / "s.ply"), "--material", "skin1", "--light", "directional:0,0,-1",
               "--width", "16", "--height", "12", "--spp", "1", "--camera", "persp:0,0,100:0,0,200:0,1,0:30",
               "--out", str(tmp_path / "img"), "-q"])
    err = capsys.readouterr().err
    assert rc == 0 and "sees none of the mesh" in err and "bounds" in err
    assert len([x for x in err.splitlines() if "sees none" in x]) == 1
