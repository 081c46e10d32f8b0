"""Environment and area lights through the command line (issue 43): ``--light env:FILE.exr[:strength[:rotation
[:up]]]``, ``uniform[:L]``, ``area:...`` and ``--light-error`` in bake, render, mc and batches.

Bad input is a clean failure (tests/cli/conftest.py: exit code 2, one ``meshshade: error:`` line naming the file,
field or value, no traceback, nothing written). A good light bakes, and the outputs' numbers are the Python API's.
"""
from __future__ import annotations

import numpy as np
import pytest

from meshshade.geometry.procedural import icosphere
from meshshade.io import load_mesh, read_baked_ply, write_exr, write_ply
from meshshade.light import AreaLight, EnvironmentLight
from meshshade.light.environment import environment_from_rgb
from meshshade.materials import Material
from meshshade.transport import bake

SKIN = ["--material", "skin1"]


@pytest.fixture
def work(tmp_path):
    """A 10 mm icosphere (162 vertices) as ``s.ply`` and a 16 x 8 sky with a bright spot as ``sky.exr``."""
    write_ply(tmp_path / "s.ply", *icosphere(10.0, 2))
    img = np.full((8, 16, 3), 0.2, np.float32)
    img[2, 5] = 40.0
    write_exr(tmp_path / "sky.exr", img)
    return tmp_path


def _raw_exr(path, img):
    import OpenImageIO as oiio
    img = np.ascontiguousarray(img, np.float32)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(img.shape[1], img.shape[0], img.shape[2], "float"))
    assert out.write_image(img)
    out.close()


def _fails(cli, work, argv, *needles):
    before = cli.snapshot(work)
    rc, _, err = cli.run(argv)
    return cli.assert_clean_failure(rc, err, before, work, *needles)


@pytest.mark.parametrize("command", ["bake", "mc"])
@pytest.mark.parametrize("make,spec,needles", [
    (None, "env:{w}/missing.exr", ("missing.exr", "does not exist")),
    ("square", "env:{w}/square.exr", ("square.exr", "twice as wide")),
    ("nan", "env:{w}/nan.exr", ("nan.exr", "nan or infinite")),
    ("negative", "env:{w}/neg.exr", ("neg.exr", "negative")),
    ("garbage", "env:{w}/garbage.exr", ("garbage.exr", "cannot be read")),
    (None, "env:{w}/sky.exr:-2", ("strength", "> 0")),
    (None, "env:{w}/sky.exr:1:30:x", ("strength, rotation",)),
    (None, "uniform:0", ("uniform radiance", "> 0")),
    (None, "area:0,0,30:0,0,-1:rect:4", ("width,height",)),
    (None, "area:0,0,30:0,0,-1:oval:4", ("rect or disc",)),
    (None, "area:0,0,30:0,0,-1:disc:4:-1", ("power", "> 0")),
    (None, "area:0,0,1:0,0,-1:disc:1", ("area light 0", "inside the mesh")),
    (None, "area:0,0,30:0,0,1:disc:1", ("behind the emitter",)),
])
def test_bad_environment_and_area_lights(cli, work, command, make, spec, needles):
    if make == "square":
        write_exr(work / "square.exr", np.ones((8, 8, 3), np.float32))
    elif make in ("nan", "negative"):
        img = np.ones((8, 16, 3), np.float32)
        img[1, 1, 0] = np.nan if make == "nan" else -0.5
        _raw_exr(work / ("nan.exr" if make == "nan" else "neg.exr"), img)
    elif make == "garbage":
        (work / "garbage.exr").write_bytes(b"\x00" * 64)
    argv = [command, work / "s.ply", *SKIN, "--light", spec.format(w=work), "--out", work / "o.ply", "-q"]
    if command == "mc":
        argv += ["--photons", "1000"]
    _fails(cli, work, argv, *needles)


@pytest.mark.parametrize("value", ["0", "0.9", "nan"])
def test_light_error_outside_its_domain(cli, work, value):
    argv = ["bake", work / "s.ply", *SKIN, "--light", "uniform", "--light-error", value, "--out", work / "o.ply"]
    _fails(cli, work, argv, "error")


def test_bake_under_a_map_and_an_area_light_is_the_apis(cli, work):
    out = work / "o.ply"
    rc, _, err = cli.run(["bake", work / "s.ply", *SKIN, "--light", f"env:{work}/sky.exr:2e-3:45",
                          "--light", "area:0,0,30:0,0,-1:disc:5:0.2", "--light-error", "0.02", "--out", out, "-q"])
    assert rc == 0, err
    _mesh, got, _info = read_baked_ply(out)
    mesh = load_mesh(work / "s.ply")
    rgb = np.full((8, 16, 3), 0.2)
    rgb[2, 5] = 40.0
    lights = [environment_from_rgb(rgb, strength=2e-3, rotation_deg=45.0, error=0.02),
              AreaLight((0, 0, 30.0), (0, 0, -1.0), "disc", (5.0,), 0.2, error=0.02)]
    api = bake(mesh, Material.preset("skin1"), lights).radiance
    np.testing.assert_allclose(got, api, rtol=2e-7, atol=1e-30)       # float32 in the PLY


def test_render_and_mc_take_a_uniform_sky(cli, work):
    rc, _, err = cli.run(["render", work / "s.ply", *SKIN, "--light", "uniform:1e-3", "--width", "16", "--height",
                          "16", "--spp", "1", "--out", work / "r", "-q"])
    assert rc == 0, err
    assert (work / "r.exr").exists() and (work / "r.png").exists()
    rc, _, err = cli.run(["mc", work / "s.ply", *SKIN, "--light", "uniform:1e-3", "--photons", "2000", "--seed",
                          "3", "--out", work / "m.ply", "-q"])
    assert rc == 0, err
    first = (work / "m.ply").read_bytes()
    rc, _, err = cli.run(["mc", work / "s.ply", *SKIN, "--light", "uniform:1e-3", "--photons", "2000", "--seed",
                          "3", "--out", work / "m2.ply", "-q"])
    assert rc == 0 and (work / "m2.ply").read_bytes() == first


def test_batch_resolves_a_map_against_the_job_file(cli, work):
    (work / "jobs").mkdir()
    (work / "jobs" / "maps").mkdir()
    write_exr(work / "jobs" / "maps" / "sky.exr", np.full((8, 16, 3), 0.5, np.float32))
    (work / "jobs" / "jobs.toml").write_text(
        '[[job]]\nname = "sky"\ncommand = "bake"\nmesh = "../s.ply"\nmaterial = "skin1"\n'
        'light = "env:maps/sky.exr:1e-3"\nlight-error = 0.05\nout = "sky.ply"\n')
    rc, _, err = cli.run(["batch", work / "jobs" / "jobs.toml", "--out", work / "res", "--workers", "1", "-q"])
    assert rc == 0, err
    assert (work / "res" / "sky" / "sky.ply").exists()


def test_api_lights_from_the_same_map_are_equal(work):
    a = environment_from_rgb(np.full((8, 16, 3), 0.5), strength=2.0)
    b = EnvironmentLight(np.full((8, 16), 0.5), strength=2.0)
    assert a == b and hash(a) == hash(b)
