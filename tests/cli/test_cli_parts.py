"""`meshshade bake --material PRESET --material PART=PRESET` (issue 49, docs/physics.md §17 "Parts"): a part named
by an OBJ's usemtl or g takes its own preset, a plain preset the rest; the same as the API's PartedMaterial; bad
input is a clean failure (exit 2, one line, nothing written); a job file's repeatable ``material`` key."""
import numpy as np
import pytest

from meshshade.cli.jobs import job_argv, read_jobs
from meshshade.geometry.procedural import nested_spheres
from meshshade.io import load_mesh
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.parts import PartedMaterial
from meshshade.transport.baking import bake

SUN = "directional:0,0,-1"


@pytest.fixture
def nested_obj(tmp_path):
    """A 10 mm skin sphere (usemtl skin, g outer) with a 4 mm ball inside (usemtl stone, g ball)."""
    V, F, part = nested_spheres(10.0, 4.0, 2, 1)
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in V]
    current = None
    for f, k in zip(F, part):
        if k != current:
            lines += ["g outer", "usemtl skin"] if k == 0 else ["g ball", "usemtl stone"]
            current = k
        lines.append("f %d %d %d" % tuple(f + 1))
    (tmp_path / "nested.obj").write_text("\n".join(lines) + "\n")
    return tmp_path


def test_a_part_by_its_usemtl_name_bakes_as_the_api_parts(cli, nested_obj):
    rc, _, err = cli.run(["bake", nested_obj / "nested.obj", "--material", "skin1", "--material", "stone=marble",
                          "--light", SUN, "--out", nested_obj / "out.ply", "--npz", nested_obj / "out.npz",
                          "--quiet"])
    assert rc == 0, err
    got = np.load(nested_obj / "out.npz")["radiance"]
    mesh = load_mesh(nested_obj / "nested.obj")
    _, _, part = nested_spheres(10.0, 4.0, 2, 1)
    pm = PartedMaterial([Material.preset("marble"), Material.preset("skin1")], 1 - part, ["stone", "rest"])
    ref = bake(mesh, pm, DirectionalLight([0, 0, -1.0], 1.0)).radiance
    np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-9 * ref.max())


def test_a_group_name_names_the_same_part(cli, nested_obj):
    args = ["bake", nested_obj / "nested.obj", "--material", "skin1", "--light", SUN, "--quiet"]
    rc, _, err = cli.run(args + ["--material", "ball=marble", "--npz", nested_obj / "g.npz", "--out",
                                 nested_obj / "g.ply"])
    assert rc == 0, err
    rc, _, err = cli.run(args + ["--material", "stone=marble", "--npz", nested_obj / "m.npz", "--out",
                                 nested_obj / "m.ply"])
    assert rc == 0, err
    np.testing.assert_array_equal(np.load(nested_obj / "g.npz")["radiance"], np.load(nested_obj / "m.npz")["radiance"])


@pytest.mark.parametrize("extra, needles", [
    (["--material", "skin1", "--material", "pebble=marble"], ("no part named 'pebble'", "skin, stone, outer, ball")),
    (["--material", "stone=marble"], ("in none of the parts",)),
    (["--material", "skin1", "--material", "marble"], ("--material given 2 times",)),
    (["--material", "skin1", "--material", "stone="], ("PART=PRESET",)),
    (["--material", "skin1", "--material", "stone=marble", "--model", "dipole"], ("material of parts",)),
    (["--material", "skin1", "--material", "stone=regular-milk"], ("index-matched",)),
    (["--material", "skin1", "--material", "stone=nosuch"], ("nosuch",)),
])
def test_bad_parts_are_a_clean_failure(cli, nested_obj, extra, needles):
    before = cli.snapshot(nested_obj)
    rc, _, err = cli.run(["bake", nested_obj / "nested.obj", "--light", SUN, "--out", nested_obj / "out.ply",
                          *extra])
    cli.assert_clean_failure(rc, err, before, nested_obj, *needles)


def test_other_commands_refuse_a_part_material(cli, nested_obj):
    before = cli.snapshot(nested_obj)
    rc, _, err = cli.run(["compare", nested_obj / "nested.obj", "--material", "stone=marble", "--light", SUN,
                          "--out", nested_obj / "cmp"])
    cli.assert_clean_failure(rc, err, before, nested_obj, "is for `meshshade bake` and `render`")


def test_a_job_file_takes_the_material_key_as_a_list(nested_obj):
    (nested_obj / "jobs.toml").write_text(
        '[[job]]\ncommand = "bake"\nname = "parts"\nmesh = "nested.obj"\n'
        'material = ["skin1", "stone=marble"]\nlight = "directional:0,0,-1"\nout = "out.ply"\n')
    jobs = read_jobs(nested_obj / "jobs.toml")
    argv = job_argv(jobs[0], nested_obj / "parts")
    assert "--material=skin1" in argv and "--material=stone=marble" in argv


def test_a_part_given_by_its_coefficients_is_that_medium(cli, nested_obj):
    """PART=SIGMA_S_PRIME/SIGMA_A[/ETA] (1/mm) bakes as the preset of those coefficients (marble's, written out from
    Jensen et al. 2001 Table 2 here), bit for bit."""
    base = ["bake", nested_obj / "nested.obj", "--material", "skin1", "--light", SUN, "--quiet"]
    rc, _, err = cli.run(base + ["--material", "stone=2.19,2.62,3.00/0.0021,0.0041,0.0071/1.3", "--npz",
                                 nested_obj / "c.npz", "--out", nested_obj / "c.ply"])
    assert rc == 0, err
    rc, _, err = cli.run(base + ["--material", "stone=marble", "--npz", nested_obj / "m.npz", "--out",
                                 nested_obj / "m.ply"])
    assert rc == 0, err
    np.testing.assert_array_equal(np.load(nested_obj / "c.npz")["radiance"], np.load(nested_obj / "m.npz")["radiance"])


@pytest.mark.parametrize("spec, needle", [("1,1,1/0.1/1.3/2", "SIGMA_S_PRIME/SIGMA_A[/ETA]"),
                                          ("abc/0.1", "comma-separated numbers"),
                                          ("1,2/0.1", "expected 1 or 3 value(s)"),
                                          ("1/-0.1", "sigma_a"),
                                          ("1/0.1/1.5", "index-matched")])
def test_bad_part_coefficients_are_a_clean_failure(cli, nested_obj, spec, needle):
    before = cli.snapshot(nested_obj)
    rc, _, err = cli.run(["bake", nested_obj / "nested.obj", "--material", "skin1", "--material", f"stone={spec}",
                          "--light", SUN, "--out", nested_obj / "out.ply"])
    cli.assert_clean_failure(rc, err, before, nested_obj, needle)
