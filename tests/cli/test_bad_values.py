"""Bad values corpus (issue 17): numeric domains, physics guards and wrong diagnoses, through the CLI and the API.

Families: eta outside the F_dr fit's domain [1, 2.5]; light strengths that overflow or carry nothing; Drago bias,
compare floor, profile rtol/azimuth/models, image size, Monte Carlo counts and budgets outside their domains; a wide
beam around a small mesh taken for a miss; camera messages that name the wrong problem; photon counts that cannot
finish; scenes whose light reaches nothing; compare checking its arguments only after the first model.

Every CLI case is a clean failure (``cli.assert_clean_failure``, tests/cli/conftest.py: exit 2, one line naming the
option, value or light, no traceback, no file left) or a success with finite outputs. The API cases check that the
Python API refuses the same values by itself (the CLI is a thin layer over it).
"""
from __future__ import annotations

import numpy as np
import pytest

from meshshade.errors import LightError, MaterialError, MeshshadeError
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.io import write_ply
from meshshade.light import BeamLight, DirectionalLight
from meshshade.materials import Material
from meshshade.montecarlo import MCOptions
from meshshade.montecarlo.simulation import check_mc_options, simulate
from meshshade.output import compare as cmp_mod
from meshshade.output.compare import CompareOptions, run_comparison
from meshshade.output.render import auto_camera, check_image_size, render_radiance
from meshshade.output.tonemap import drago_tonemap, tonemap
from meshshade.profiles import Shape, profile_distances, profile_rows, reflectance_profile
from meshshade.transport import BakeOptions, SurfaceOptions
from meshshade.transport.baking import bake

SKIN = ["--material", "skin1"]
BEAM = ["--light", "beam:0,0,40:0,0,-1"]
SMALL_IMAGE = ["--width", "24", "--height", "24", "--spp", "1"]


@pytest.fixture
def work(tmp_path):
    """A folder holding a 10 mm icosphere (162 vertices) as ``s.ply``."""
    write_ply(tmp_path / "s.ply", *icosphere(10.0, 2))
    return tmp_path


def _plate(tmp_path):
    """An open 10 x 10 mm plate facing +z (121 vertices) as ``plate.ply``."""
    xs = np.linspace(-5, 5, 11)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    V = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    F = [(i * 11 + j, (i + 1) * 11 + j, (i + 1) * 11 + j + 1) for i in range(10) for j in range(10)]
    F += [(i * 11 + j, (i + 1) * 11 + j + 1, i * 11 + j + 1) for i in range(10) for j in range(10)]
    write_ply(tmp_path / "plate.ply", V, np.array(F))
    return tmp_path / "plate.ply"


def _fails(cli, work, argv, *needles):
    before = cli.snapshot(work)
    rc, _, err = cli.run(argv)
    return cli.assert_clean_failure(rc, err, before, work, *needles)


# --------------------------------------------------------------------------------------------- CLI: profile
@pytest.mark.parametrize("opts,needles", [
    (["--eta", "100"], ("eta", "[1, 2.5]", "100")),     # F_dr > 1: negative reflectance before issue 17
    (["--eta", "60"], ("eta", "[1, 2.5]")),
    (["--eta", "0.5"], ("eta", "[1, 2.5]", "0.5")),     # F_dr < 0
    (["--models", ""], ("models",)),                     # TypeError traceback before issue 17
    (["--models", "dipole,dipole"], ("dipole", "twice")),
    (["--models", "dipole,bogus"], ("bogus",)),
    (["--rtol", "0", "--shape", "sphere", "--radius", "5"], ("rtol", "[1e-15, 0.1]")),   # tracebacks before
    (["--rtol", "-1"], ("rtol", "[1e-15, 0.1]")),
    (["--rtol", "1"], ("rtol", "[1e-15, 0.1]")),
    (["--azimuth", "nan", "--shape", "cylinder", "--radius", "5"], ("azimuth",)),
    (["--distances", "1,-2"], ("distances",)),
])
def test_profile_bad_values(cli, tmp_path, opts, needles):
    argv = ["profile", *SKIN, *(["--distances", "0.5,1"] if "--distances" not in opts else []), *opts]
    _fails(cli, tmp_path, argv, *needles)


def test_profile_eta_in_the_grey_zone_warns_and_stays_positive(cli, tmp_path):
    rc, out, err = cli.run(["profile", *SKIN, "--eta", "2.4", "--distances", "0.5,1,2"])
    assert rc == 0 and "Traceback" not in err
    assert "meshshade: warning:" in err and "eta = 2.4 is above 2.2" in err
    values = [float(x) for line in out.splitlines() if not line.startswith("#") for x in line.split()[1:]
              if x[0] in "0123456789-"]
    assert values and min(values) > 0.0


# --------------------------------------------------------------------------------------------- CLI: lights
@pytest.mark.parametrize("spec,needles", [
    ("directional:0,0,-1:1e308", ("irradiance", "1e20", "1e308")),   # inf radiance, exit 0 before issue 17
    ("beam:0,0,40:0,0,-1:1e21", ("power", "1e20")),
    ("beam:0,0,40:0,0,-1:0", ("power", "> 0")),
    ("point:0,0,40:0", ("intensity", "> 0")),
])
@pytest.mark.parametrize("command", ["bake", "mc"])
def test_light_strength_outside_its_domain(cli, work, command, spec, needles):
    _fails(cli, work, [command, work / "s.ply", *SKIN, "--light", spec, "--out", work / "o.ply", "-q"], *needles)


def test_bake_eta_outside_the_domain(cli, work):
    _fails(cli, work, ["bake", work / "s.ply", *SKIN, "--eta", "60", *BEAM, "--out", work / "o.ply", "-q"],
           "eta", "[1, 2.5]")


def test_strongest_allowed_light_gives_finite_outputs(cli, work):
    """MAX_LIGHT_STRENGTH = 1e20 keeps the radiance finite, also in the float32 PLY."""
    rc, _, err = cli.run(["bake", work / "s.ply", *SKIN, "--light", "directional:0,0,-1:1e20", "--out",
                          work / "o.ply", "--npz", work / "o.npz", "-q"])
    assert rc == 0, err
    M = np.load(work / "o.npz")["radiance"]
    assert np.all(np.isfinite(M)) and M.min() >= 0.0 and 0.0 < M.max() < np.finfo(np.float32).max


@pytest.mark.parametrize("command", ["bake", "mc"])
def test_wide_beam_around_a_small_sphere_is_not_a_miss(cli, work, command):
    """Issue 17: beam:0,0,40:0,0,-1:1:150 on a 10 mm sphere (axis through the centre) was "misses the mesh"."""
    argv = [command, work / "s.ply", *SKIN, "--light", "beam:0,0,40:0,0,-1:1:150", "--out", work / "o.ply",
            "--npz", work / "o.npz", "-q"] + (["--photons", "2000"] if command == "mc" else [])
    rc, _, err = cli.run(argv)
    assert rc == 0 and "Traceback" not in err, err
    M = np.load(work / "o.npz")["radiance"]
    assert np.all(np.isfinite(M)) and M.min() >= 0.0 and M.max() > 0.0


@pytest.mark.parametrize("command", ["bake", "mc"])
@pytest.mark.parametrize("spec,needles", [
    ("beam:0,0,40:0,0,-1:1:5", ()),     # still a miss: nothing of the sphere lies in the cylinder
    ("beam:0,0,40:0,0,1", ("did you mean direction 0,0,-1",)),
])
def test_a_beam_that_really_misses(cli, work, command, spec, needles):
    spec = spec.replace("0,0,40", "30,0,40") if spec.endswith(":5") else spec
    _fails(cli, work, [command, work / "s.ply", *SKIN, "--light", spec, "--out", work / "o.ply", "-q"],
           "beam light 0", "misses the mesh", *needles)


@pytest.mark.parametrize("command", ["bake", "mc"])
def test_one_light_among_several_reaching_nothing_is_a_warning(cli, tmp_path, command):
    """The plate faces +z: directional:0,0,1 (from below) reaches nothing, directional:0,0,-1 lights it. One
    warning naming the dark light (with the reversed direction), exit 0, a lit result. Alone, the dark light is
    an error: tests/cli/test_bad_input.py::test_light_reaching_no_vertex_is_a_warning."""
    plate = _plate(tmp_path)
    rc, _, err = cli.run([command, plate, *SKIN, "--light", "directional:0,0,1", "--light", "directional:0,0,-1",
                          "--out", tmp_path / "o.ply", "--npz", tmp_path / "o.npz", "-q"]
                         + (["--photons", "2000"] if command == "mc" else []))
    assert rc == 0 and "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert all(line.startswith("meshshade: warning:") for line in lines)
    dark = [line for line in lines if "directional light 0" in line]
    assert len(dark) == 1 and "reaches no vertex" in dark[0] and "directional:0,0,-1" in dark[0]
    assert np.load(tmp_path / "o.npz")["radiance"].max() > 0.0


@pytest.mark.parametrize("command", ["render", "compare"])
def test_no_light_reaching_the_mesh_is_an_error_in_render_and_compare(cli, tmp_path, command):
    plate = _plate(tmp_path)
    _fails(cli, tmp_path, [command, plate, *SKIN, "--light", "directional:0,0,1", *SMALL_IMAGE, "--out",
                           tmp_path / "out", "-q"], "directional light 0", "reaches no vertex")


# --------------------------------------------------------------------------------------------- CLI: images
@pytest.mark.parametrize("opts,needles", [
    (["--bias", "-1"], ("bias", "(0, 1]")),          # garbage PNG before issue 17
    (["--bias", "0"], ("bias", "(0, 1]")),
    (["--bias", "1.5"], ("bias", "(0, 1]")),
    (["--bias", "nan"], ("bias",)),
    (["--width", "100000", "--height", "100000"], ("100000 x 100000", "GiB")),   # MemoryError before
    (["--camera", "auto:0,0,0"], ("auto view direction", "non-zero")),           # "eye and target must differ"
    (["--camera", "persp:0,0,40:0,0,0:0,0,0:30"], ("up vector must be non-zero",)),
    (["--camera", "persp:0,0,40:0,0,0:0,0,1:30"], ("up vector", "parallel")),
    (["--camera", "persp:0,0,40:0,0,40:0,1,0:30"], ("eye and target must differ",)),
    (["--camera", "persp:0,0,40:0,0,0:0,1,0:180"], ("fov", "(0, 180)")),
    (["--camera", "ortho:0,0,40:0,0,0:0,1,0:-2"], ("orthographic", "height", "> 0")),
    (["--camera", "auto:1,2"], ("auto view direction", "3 comma-separated numbers")),
])
def test_render_bad_values(cli, work, opts, needles):
    size = [] if "--width" in opts else SMALL_IMAGE
    _fails(cli, work, ["render", work / "s.ply", *SKIN, *BEAM, *size, *opts, "--out", work / "r", "-q"], *needles)


@pytest.mark.parametrize("opts,needles", [
    (["--floor", "0"], ("floor", "(0, 1)")),
    (["--floor", "1"], ("floor", "(0, 1)")),
    (["--floor", "nan"], ("floor",)),               # null statistics before issue 17
    (["--models", "curved,curved"], ("curved", "two different models")),
    (["--models", "curved,bogus"], ("bogus",)),
    (["--models", "mc,dipole", "--photons", "1180591620717411303424"], ("photons", "2^62")),
    (["--width", "100000", "--height", "100000"], ("GiB",)),
    (["--cutoff-tol", "2"], ("cutoff",)),
])
def test_compare_bad_values_are_refused_before_any_work(cli, work, monkeypatch, opts, needles):
    """run_comparison checks every argument before the first bake (it checked some after it before issue 17)."""
    def no_work(*args, **kwargs):
        raise AssertionError("work started before the arguments were checked")

    monkeypatch.setattr(cmp_mod, "bake", no_work)
    monkeypatch.setattr(cmp_mod, "simulate", no_work)
    _fails(cli, work, ["compare", work / "s.ply", *SKIN, *BEAM, *SMALL_IMAGE, *opts, "--out", work / "cmp", "-q"],
           *needles)


# --------------------------------------------------------------------------------------------- CLI: mc
@pytest.mark.parametrize("opts,needles", [
    (["--photons", "1180591620717411303424"], ("photons", "2^62", "would take at least")),   # ran for ever
    (["--photons", "100000000000000"], ("would take at least", "day", "--time-budget")),
    (["--time-budget", "nan"], ("time-budget",)),                                            # ignored before
    (["--time-budget", "0"], ("time_budget", "> 0")),
    (["--pool", "100000000"], ("pool", "[1, 4194304]")),
])
def test_mc_bad_values(cli, work, opts, needles):
    _fails(cli, work, ["mc", work / "s.ply", *SKIN, *BEAM, *opts, "--out", work / "o.ply", "-q"], *needles)


# --------------------------------------------------------------------------------------------- the API itself
@pytest.fixture(scope="module")
def sphere_mesh():
    return Mesh.from_arrays(*icosphere(10.0, 1))


@pytest.mark.parametrize("kwargs,needle", [
    (dict(bias=np.nan), "bias"), (dict(bias=-1.0), "bias"), (dict(bias=0.0), "bias"), (dict(bias=1.0001), "bias"),
    (dict(exposure=np.nan), "exposure"), (dict(exposure=0.0), "exposure"), (dict(operator="reinhard"), "reinhard"),
])
def test_api_tonemap_domains(kwargs, needle):
    with pytest.raises(MeshshadeError, match=needle):
        tonemap(np.ones((2, 2, 3)), **kwargs)


def test_api_drago_edges_of_the_domain_are_finite():
    rgb = np.geomspace(1e-6, 1.0, 30)[:, None].repeat(3, axis=1)
    for bias in (1e-3, 1.0):
        out = drago_tonemap(rgb, bias=bias)
        assert np.all(np.isfinite(out)) and np.all(np.diff(out[:, 1]) >= 0)
    with pytest.raises(MeshshadeError, match="L_dmax"):
        drago_tonemap(rgb, L_dmax=np.inf)


@pytest.mark.parametrize("call,needle", [
    (lambda: profile_rows(Material(1.0, 0.01), [1.0], models=[], shapes=[Shape("plane")]), "models"),
    (lambda: profile_rows(Material(1.0, 0.01), [1.0], models=["exact", "exact"], shapes=[Shape("plane")]), "twice"),
    (lambda: profile_rows(Material(1.0, 0.01), [1.0], models=["dipole"], shapes=[]), "shapes"),
    (lambda: profile_rows(Material(1.0, 0.01), [1.0], models=["dipole"], shapes=[Shape("plane")],
                          azimuths_deg=[]), "azimuth"),
    (lambda: reflectance_profile(Material(1.0, 0.01), [1.0], rtol=0.0), r"rtol .*\[1e-15, 0\.1\]"),
    (lambda: reflectance_profile(Material(1.0, 0.01), [1.0], rtol=np.nan), "rtol"),
    (lambda: reflectance_profile(Material(1.0, 0.01), [1.0], azimuth_deg=np.inf), "azimuth"),
    (lambda: reflectance_profile(Material(1.0, 0.01), [np.nan]), "distances"),
    (lambda: reflectance_profile(Material(1.0, 0.01), []), "distances"),
    (lambda: profile_distances(0.0, 41), "max distance"),
    (lambda: profile_distances(-1.0, 41), "max distance"),
    (lambda: profile_distances(np.nan, 41), "max distance"),
    (lambda: profile_distances(20.0, 1), "samples"),
    (lambda: profile_distances(20.0, 2.5), "samples"),
    (lambda: Shape.make("sphere", radius_mm=np.nan), "radius"),
    (lambda: Shape.make("point", k1=np.inf, k2=0.0), "k1"),
])
def test_api_profile_domains(call, needle):
    with pytest.raises(MeshshadeError, match=needle):
        call()


def test_api_profile_rtol_edges_are_accepted():
    for rtol in (1e-15, 0.1):
        R = reflectance_profile(Material(1.0, 0.01), [0.5, 1.0], model="exact", shape=Shape.make("sphere", 5.0),
                                rtol=rtol)
        assert np.all(np.isfinite(R)) and np.all(R > 0)
    assert profile_distances(20.0, 2).tolist() == [0.0, 20.0]


@pytest.mark.parametrize("kwargs,needle", [
    (dict(photons=2 ** 70), "2\\^62"), (dict(photons=10 ** 14), "would take at least"),
    (dict(photons=15), r"photons must be an integer >= 16"), (dict(photons=1.5), "photons"),
    (dict(photons=None), "photon count or a time budget"),
    (dict(time_budget=np.nan), "time_budget"), (dict(time_budget=-1.0), "time_budget"),
    (dict(time_budget=np.inf), "time_budget"),
    (dict(seed=-1), "seed"), (dict(seed=2 ** 64), "seed"), (dict(seed=1.5), "seed"),
    (dict(pool=0), "pool"), (dict(pool=1 << 30), "pool"), (dict(n_batches=1), "n_batches"),
    (dict(engine="gpu"), "engine"),
])
def test_api_mc_domains(kwargs, needle):
    with pytest.raises(MeshshadeError, match=needle):
        check_mc_options(**{"photons": 1000, **kwargs})


def test_api_mc_refuses_before_any_work(sphere_mesh, monkeypatch):
    """simulate checks its arguments before the scene, grid and emitter are built."""
    import meshshade.montecarlo.simulation as sim

    monkeypatch.setattr(sim, "make_scene", lambda *a, **k: pytest.fail("work started"))
    with pytest.raises(MeshshadeError, match="time_budget"):
        simulate(sphere_mesh, Material(1.0, 0.01), [BeamLight((0, 0, 40), (0, 0, -1))], MCOptions(time_budget=np.nan))
    assert check_mc_options(1e5, seed=3.0) == (100_000, 3, None, 16, None)   # integral floats are counts
    assert check_mc_options(10 ** 14, time_budget=2.0)[0] == 10 ** 14        # a budget bounds any count


@pytest.mark.parametrize("size,needle", [
    ((100_000, 100_000, 4), "GiB"), ((0, 10, 1), "width"), ((10, -1, 1), "height"), ((10, 10, 0), "spp"),
    ((10.5, 10, 1), "width"), ((np.nan, 10, 1), "width"), ((512, 512, 10 ** 9), "pixel samples"),
])
def test_api_image_size(sphere_mesh, size, needle):
    with pytest.raises(MeshshadeError, match=needle):
        check_image_size(*size)
    with pytest.raises(MeshshadeError, match=needle):
        render_radiance(sphere_mesh, np.zeros((sphere_mesh.n_vertices, 3)), auto_camera(sphere_mesh), *size)


def _image(**kw):
    return CompareOptions(**{"width": 8, "height": 8, "spp": 1, **kw})


@pytest.mark.parametrize("call,needle", [
    (lambda r: r(options=_image(floor=np.nan)), "floor"), (lambda r: r(options=_image(floor=0.0)), "floor"),
    (lambda r: r(options=_image(floor=1.0)), "floor"), (lambda r: r(models=("curved",)), "exactly two"),
    (lambda r: r(models=("curved", "curved")), "different"), (lambda r: r(models=("curved", "nope")), "nope"),
    (lambda r: r(models=("mc", "dipole"), mc=MCOptions(photons=0)), "photons"),
    (lambda r: r(models=("mc", "dipole"), mc=MCOptions(seed=-1)), "seed"),
    (lambda r: r(models=("mc", "dipole"), mc=MCOptions(photons=2 ** 61)), "photons"),   # the run's estimate
    (lambda r: r(options=_image(width=0)), "width"), (lambda r: r(options=_image(spp=1.5)), "spp"),
    (lambda r: r(surface=SurfaceOptions(cutoff_tol=np.nan)), "cutoff"),
    (lambda r: r(surface=SurfaceOptions(geodesic="straight")), "geodesic"),
    (lambda r: r(models=("volume", "dipole"), surface=SurfaceOptions(far_field="off")), "far-field"),
    (lambda r: r(camera="auto"), "Camera"), (lambda r: r(surface={"geodesic": "arc"}), "SurfaceOptions"),
])
def test_api_run_comparison_checks_everything_first(sphere_mesh, monkeypatch, call, needle):
    monkeypatch.setattr(cmp_mod, "bake", lambda *a, **k: pytest.fail("work started"))
    monkeypatch.setattr(cmp_mod, "simulate", lambda *a, **k: pytest.fail("work started"))

    def run(**kw):
        kw = {"models": ("curved", "dipole"), "options": _image(), **kw}
        return run_comparison(sphere_mesh, Material(1.0, 0.01), [BeamLight((0, 0, 40), (0, 0, -1))], **kw)

    with pytest.raises(MeshshadeError, match=needle):
        call(run)


@pytest.mark.parametrize("kwargs,needle", [
    (dict(rtol=0.0), "rtol"), (dict(rtol=1.0), "rtol"), (dict(far_tol=np.nan), "far_tol"),
    (dict(far_rel_tol=2.0), "far_rel_tol"), (dict(cutoff_tol="small"), "cutoff"),
    (dict(curvature_radius_mm=np.nan), "curvature radius"), (dict(backend="optix"), "backend"),
    (dict(far_geodesic="none"), "far_geodesic"),
])
def test_api_bake_options(kwargs, needle):
    """The options records refuse bad values where they are made (before any bake)."""
    with pytest.raises(MeshshadeError, match=needle):
        BakeOptions(**kwargs) if "backend" in kwargs else SurfaceOptions(**kwargs)


def test_api_bake_and_mc_refuse_a_scene_without_light_that_reaches_it(sphere_mesh):
    mat = Material(1.0, 0.01)
    with pytest.raises(LightError, match="no light given"):
        bake(sphere_mesh, mat, [])
    with pytest.raises(LightError, match="at least one light"):
        simulate(sphere_mesh, mat, [], MCOptions(photons=1000))
    with pytest.raises(MaterialError, match="Material"):
        bake(sphere_mesh, "skin1", [DirectionalLight((0, 0, -1))])
