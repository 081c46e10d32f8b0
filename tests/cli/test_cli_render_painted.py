"""`meshshade render` with a painted material (`--albedo-map`) or parts (`--material PART=NAME`), as `meshshade bake`
takes them (issue 49): the image of the painted bake's own radiance, per vertex and per pixel; bad input is a clean
failure (exit 2, one line, nothing written). A job file's `albedo-map` is a file beside the job file, as its mesh."""
import numpy as np
import pytest

from meshshade.cli.jobs import job_argv, read_jobs
from meshshade.geometry.procedural import icosphere, nested_spheres, spherical_uv
from meshshade.io import read_exr, write_obj, write_png

SUN = "directional:0,0,-1"
IMAGE = ["--width", "48", "--height", "48", "--spp", "1", "--quiet"]


@pytest.fixture
def textured(tmp_path):
    """A 10 mm ball with a longitude-latitude UV map, its one part ``paint`` in a material library naming a
    two-tone sRGB PNG."""
    V, F = icosphere(10.0, 2)
    write_obj(tmp_path / "ball.obj", V, F, uv=spherical_uv(V, F))
    text = (tmp_path / "ball.obj").read_text()
    (tmp_path / "ball.obj").write_text("mtllib ball.mtl\nusemtl paint\n" + text)
    (tmp_path / "ball.mtl").write_text("newmtl paint\nKd 1 1 1\nmap_Kd paint.png\n")
    img = np.full((8, 8, 3), 200, dtype=np.uint8)
    img[:, :4] = (90, 40, 30)
    write_png(tmp_path / "paint.png", img)
    return tmp_path


def _exr(path):
    return read_exr(path)[0]


def test_render_paints_as_bake_does(cli, textured):
    """The painted render equals the render of the painted bake's PLY (the same radiance, read back at float32),
    and differs from the plain material's."""
    rc, _, err = cli.run(["bake", textured / "ball.obj", "--material", "skin1", "--albedo-map", "mtl", "--light",
                          SUN, "--out", textured / "b.ply", "--quiet"])
    assert rc == 0, err
    rc, _, err = cli.run(["render", textured / "b.ply", "--out", textured / "from_ply", *IMAGE])
    assert rc == 0, err
    rc, _, err = cli.run(["render", textured / "ball.obj", "--material", "skin1", "--albedo-map", "mtl", "--light",
                          SUN, "--out", textured / "painted", *IMAGE])
    assert rc == 0, err
    rc, _, err = cli.run(["render", textured / "ball.obj", "--material", "skin1", "--light", SUN, "--out",
                          textured / "plain", *IMAGE])
    assert rc == 0, err
    painted, from_ply, plain = (_exr(textured / f"{n}.exr") for n in ("painted", "from_ply", "plain"))
    rgb = slice(0, 3)
    np.testing.assert_allclose(painted[..., rgb], from_ply[..., rgb], rtol=1e-5, atol=1e-6 * painted.max())
    lit = plain[..., rgb] > 1e-3 * plain[..., rgb].max()
    assert np.mean(np.abs(painted[..., rgb][lit] / plain[..., rgb][lit] - 1)) > 0.05


def test_per_pixel_render_of_a_painted_material(cli, textured):
    """Per pixel, the painted medium's near field: close to the per-vertex image where the light is smooth (a sun
    on a ball), and not the plain material's."""
    base = ["render", textured / "ball.obj", "--material", "skin1", "--light", SUN, *IMAGE]
    for name, extra in (("pp", ["--albedo-map", "mtl", "--per-pixel"]), ("pv", ["--albedo-map", "mtl"]),
                        ("plain_pp", ["--per-pixel"])):
        rc, _, err = cli.run(base + extra + ["--out", textured / name])
        assert rc == 0, err
    pp, pv, plain = (_exr(textured / f"{n}.exr")[..., :3] for n in ("pp", "pv", "plain_pp"))
    lit = pv > 0.05 * pv.max()
    assert np.median(np.abs(pp[lit] / pv[lit] - 1)) < 0.05
    assert np.median(np.abs(pp[lit] / plain[lit] - 1)) > 0.05


def test_render_takes_parts(cli, tmp_path):
    """A part's preset changes the image; an unknown part is a clean failure."""
    V, F, part = nested_spheres(10.0, 4.0, 2, 1)
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in V]
    current = None
    for f, k in zip(F, part):
        if k != current:
            lines += ["usemtl skin"] if k == 0 else ["usemtl stone"]
            current = k
        lines.append("f %d %d %d" % tuple(f + 1))
    (tmp_path / "nested.obj").write_text("\n".join(lines) + "\n")
    base = ["render", tmp_path / "nested.obj", "--material", "skin1", "--light", SUN, *IMAGE]
    rc, _, err = cli.run(base + ["--material", "stone=ketchup", "--out", tmp_path / "parts"])
    assert rc == 0, err
    rc, _, err = cli.run(base + ["--out", tmp_path / "one"])
    assert rc == 0, err
    a, b = _exr(tmp_path / "parts.exr")[..., :3], _exr(tmp_path / "one.exr")[..., :3]
    assert np.abs(a - b).max() > 1e-3 * b.max()
    before = cli.snapshot(tmp_path)
    rc, _, err = cli.run(base + ["--material", "pebble=marble", "--out", tmp_path / "bad"])
    cli.assert_clean_failure(rc, err, before, tmp_path, "no part named 'pebble'")


def test_render_refuses_bad_paint_cleanly(cli, textured):
    V, F = icosphere(10.0, 2)
    write_obj(textured / "plain.obj", V, F)
    before = cli.snapshot(textured)
    cases = [(textured / "ball.obj", ["--albedo-map", "mtl", "--model", "dipole"], "needs the volume model"),
             (textured / "plain.obj", ["--albedo-map", textured / "paint.png"], "no texture coordinates"),
             (textured / "ball.obj", ["--albedo-map", "mtl", "--material", "paint=marble"], "paints one material")]
    for mesh, extra, needle in cases:
        rc, _, err = cli.run(["render", mesh, "--material", "skin1", *extra, "--light", SUN, "--out",
                              textured / "r", *IMAGE])
        cli.assert_clean_failure(rc, err, before, textured, needle)


def test_a_job_files_albedo_map_lies_beside_it(textured):
    (textured / "jobs.toml").write_text(
        '[[job]]\ncommand = "render"\nname = "painted"\nmesh = "ball.obj"\nmaterial = "skin1"\n'
        'albedo-map = "paint.png"\nlight = "directional:0,0,-1"\n'
        '[[job]]\ncommand = "bake"\nname = "mtl"\nmesh = "ball.obj"\nmaterial = "skin1"\n'
        'albedo-map = "mtl"\nlight = "directional:0,0,-1"\n')
    jobs = read_jobs(textured / "jobs.toml")
    assert f"--albedo-map={(textured / 'paint.png').resolve()}" in job_argv(jobs[0], textured / "painted")
    assert "--albedo-map=mtl" in job_argv(jobs[1], textured / "mtl")
