"""`meshshade bake --radius-map FILE [--radius-scale S]` (issue 49, docs/physics.md eq. (132)): a map over the UVs
read as data (no sRGB decoding) scales the material's mean free path per point; bad input is a clean failure
(exit 2, one line, nothing written)."""
import numpy as np
import OpenImageIO as oiio
import pytest

from meshshade.geometry.procedural import icosphere, spherical_uv
from meshshade.io import load_mesh, write_exr, write_obj, write_png
from meshshade.kernels.painted_reflectance import albedo_for_reflectance
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.transport.baking import bake

SUN = "directional:0,0,-1"


@pytest.fixture
def ball(tmp_path):
    """A 10 mm ball with a longitude-latitude UV map."""
    V, F = icosphere(10.0, 2)
    write_obj(tmp_path / "ball.obj", V, F, uv=spherical_uv(V, F))
    return tmp_path


def _scaled(m):
    """skin1 with its mean free path times m (the homogeneous medium a constant radius map makes)."""
    b = Material.preset("skin1")
    return Material(b.sigma_s_prime / m, b.sigma_a / m, b.eta, b.g, "scaled")


def test_a_constant_png_radius_map_is_read_as_data_and_scaled(cli, ball):
    # an 8-bit value of 128 is 128/255 as data (an sRGB decoding would make it 0.216); times --radius-scale 3
    write_png(ball / "radius.png", np.full((8, 8, 3), 128, dtype=np.uint8))
    rc, _, err = cli.run(["bake", ball / "ball.obj", "--material", "skin1", "--radius-map", ball / "radius.png",
                          "--radius-scale", "3", "--light", SUN, "--npz", ball / "r.npz", "--out", ball / "r.ply",
                          "--quiet"])
    assert rc == 0, err
    got = np.load(ball / "r.npz")["radiance"]
    ref = bake(load_mesh(ball / "ball.obj"), _scaled(3 * 128 / 255), DirectionalLight([0, 0, -1.0], 1.0)).radiance
    lit = ref > 1e-3 * ref.max(axis=0)
    np.testing.assert_allclose(got[lit], ref[lit], rtol=1e-6)


def test_a_grey_exr_radius_map_with_an_albedo_map(cli, ball):
    out = oiio.ImageOutput.create(str(ball / "radius.exr"))        # one channel: the factor for r, g and b
    out.open(str(ball / "radius.exr"), oiio.ImageSpec(8, 4, 1, oiio.FLOAT))
    out.write_image(np.full((4, 8, 1), 1.7, dtype=np.float32))
    out.close()
    write_exr(ball / "paint.exr", np.full((4, 8, 3), 0.3, dtype=np.float32))
    rc, _, err = cli.run(["bake", ball / "ball.obj", "--material", "skin1", "--radius-map", ball / "radius.exr",
                          "--albedo-map", ball / "paint.exr", "--light", SUN, "--npz", ball / "r.npz",
                          "--out", ball / "r.ply", "--quiet"])
    assert rc == 0, err
    got = np.load(ball / "r.npz")["radiance"]
    b = Material.preset("skin1")
    a = albedo_for_reflectance(np.full(3, np.float32(0.3)), b.eta, b.g)
    st = b.sigma_t_prime / np.float32(1.7)
    ref = bake(load_mesh(ball / "ball.obj"), Material(a * st, (1 - a) * st, b.eta), DirectionalLight([0, 0, -1.0],
                                                                                                       1.0)).radiance
    lit = ref > 1e-3 * ref.max(axis=0)
    np.testing.assert_allclose(got[lit], ref[lit], rtol=1e-6)


def test_bad_radius_maps_are_refused(cli, ball):
    write_png(ball / "zero.png", np.zeros((8, 8, 3), dtype=np.uint8))
    write_png(ball / "radius.png", np.full((8, 8, 3), 200, dtype=np.uint8))
    (ball / "bad.png").write_text("not an image")
    V, F = icosphere(10.0, 2)
    write_obj(ball / "plain.obj", V, F)
    before = cli.snapshot(ball)
    cases = [("ball.obj", ["--radius-map", ball / "zero.png"], "texel(s) of 0 or below"),
             ("ball.obj", ["--radius-map", ball / "bad.png"], "cannot read the radius map"),
             ("ball.obj", ["--radius-map", ball / "missing.exr"], "radius map not found"),
             ("ball.obj", ["--radius-map", ball / "radius.png", "--radius-scale", "0"], "--radius-scale must be"),
             ("ball.obj", ["--radius-scale", "2"], "give --radius-map"),
             ("ball.obj", ["--radius-map", ball / "radius.png", "--model", "dipole"], "needs the volume model"),
             ("plain.obj", ["--radius-map", ball / "radius.png"], "UVs")]
    for mesh, extra, needle in cases:
        rc, _, err = cli.run(["bake", ball / mesh, "--material", "skin1", *extra, "--light", SUN,
                              "--out", ball / "out.ply"])
        cli.assert_clean_failure(rc, err, before, ball, needle)


def test_mc_walks_the_radius_map_as_bake_reads_it(cli, ball):
    from meshshade.io import read_data_map, read_uv_map
    from meshshade.montecarlo import MCOptions, simulate
    from meshshade.painted import PaintedMaterial
    rows = np.where(np.arange(8)[:, None, None] < 4, 180, 90) * np.ones((8, 8, 3))      # two bands of latitude
    write_png(ball / "radius.png", rows.astype(np.uint8))
    rc, _, err = cli.run(["mc", ball / "ball.obj", "--material", "skin1", "--radius-map", ball / "radius.png",
                          "--radius-scale", "2", "--light", SUN, "--photons", "3000", "--seed", "3",
                          "--npz", ball / "m.npz", "--out", ball / "m.ply", "--quiet"])
    assert rc == 0, err
    mesh = load_mesh(ball / "ball.obj")
    factors = read_data_map(ball / "radius.png") * 2                # the same reading as bake's
    np.testing.assert_allclose(factors, 2 * rows / 255, rtol=1e-6)
    painted = PaintedMaterial(Material.preset("skin1"), radius_image=factors, uv=read_uv_map(ball / "ball.obj", mesh))
    ref = simulate(mesh, painted, DirectionalLight([0, 0, -1.0], 1.0), MCOptions(photons=3000, seed=3))
    np.testing.assert_array_equal(np.load(ball / "m.npz")["radiance"], ref.radiance)


def test_a_job_files_radius_map_lies_beside_it(ball):
    from meshshade.cli.jobs import job_argv, read_jobs
    (ball / "jobs.toml").write_text('[[job]]\ncommand = "bake"\nname = "r"\nmesh = "ball.obj"\nmaterial = "skin1"\n'
                                    'radius-map = "radius.exr"\nradius-scale = 2.5\nlight = "directional:0,0,-1"\n')
    argv = job_argv(read_jobs(ball / "jobs.toml")[0], ball / "r")
    assert f"--radius-map={(ball / 'radius.exr').resolve()}" in argv and "--radius-scale=2.5" in argv


def test_a_per_pixel_render_with_a_constant_radius_map_is_the_scaled_materials(cli, ball):
    # per pixel, the near field at each pixel's point in the medium there (PaintedMedium.point_near_field, eq. (133))
    from meshshade.io import read_exr
    write_exr(ball / "radius.exr", np.full((4, 8, 3), 1.7, dtype=np.float32))
    image = ["--light", SUN, "--width", "40", "--height", "40", "--spp", "1", "--per-pixel", "--quiet"]
    b = Material.preset("skin1")
    st = b.sigma_t_prime / np.float32(1.7)
    runs = {"map": ["--material", "skin1", "--radius-map", ball / "radius.exr"],
            "scaled": ["--sigma-s-prime", ",".join(repr(float(x)) for x in b.albedo_prime * st),
                       "--sigma-a", ",".join(repr(float(x)) for x in (1 - b.albedo_prime) * st), "--eta", "1.3"],
            "base": ["--material", "skin1"]}
    for name, extra in runs.items():
        rc, _, err = cli.run(["render", ball / "ball.obj", *extra, *image, "--out", ball / name])
        assert rc == 0, err
    got, ref, base = (read_exr(ball / f"{n}.exr")[0][..., :3] for n in runs)
    lit = ref > 1e-3 * ref.max()
    np.testing.assert_allclose(got[lit], ref[lit], rtol=1e-4)
    assert np.median(np.abs(base[lit] / ref[lit] - 1)) > 0.02
