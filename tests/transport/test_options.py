"""The option records of the bake, the Monte Carlo and compare (issue 48): checked where they are made, honoured,
and the former keyword arguments still working for a release, each call with a DeprecationWarning and the same
result as the records."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from meshshade.errors import MeshshadeError, ParameterError
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.light import BeamLight, DirectionalLight
from meshshade.materials import Material
from meshshade.montecarlo import MCOptions, simulate
from meshshade.output.compare import CompareOptions, run_comparison
from meshshade.surface import SurfaceTransport
from meshshade.transport import AutoTolerances, BakeOptions, SurfaceOptions, VolumeOptions, bake

SKIN = Material.preset("skin1")
SUN = [DirectionalLight((0.2, -0.1, -1.0))]


@pytest.fixture(scope="module")
def sphere():
    return Mesh.from_arrays(*icosphere(10.0, 2))


def test_the_default_needs_no_options():
    o = BakeOptions()
    assert (o.model, o.backend, o.progress) == ("volume", "embree", False)
    assert o.volume == VolumeOptions() and o.surface == SurfaceOptions()
    assert o.far_field == "clustered" and BakeOptions(model="dipole").far_field == "off"
    assert hash(o) == hash(BakeOptions())     # frozen and hashable: a key of the batch workers' caches


@pytest.mark.parametrize("make, needle", [
    (lambda: BakeOptions(model="fancy"), "unknown model 'fancy'"),
    (lambda: BakeOptions(backend="optix"), "ray backend"),
    (lambda: BakeOptions(progress=3), "progress"),
    (lambda: BakeOptions(surface={"geodesic": "arc"}), "SurfaceOptions"),
    (lambda: BakeOptions(model="volume", surface=SurfaceOptions(transport="direct")), "applies to the surface"),
    (lambda: BakeOptions(model="volume", surface=SurfaceOptions(far_field="off")), "far-field option"),
    (lambda: SurfaceOptions(geodesic="heat"), "geodesic method"),
    (lambda: SurfaceOptions(transport="fmm"), "unknown transport"),
    (lambda: SurfaceOptions(source_model="disc"), "source model"),
    (lambda: SurfaceOptions(auto={"curvature_tol": -1.0}), "curvature_tol"),
    (lambda: SurfaceOptions(auto={"speed": 1.0}), "unknown auto tolerance"),
    (lambda: VolumeOptions(h0=0.0), "lattice spacing"),
    (lambda: VolumeOptions(budget=999), "budget"),
    (lambda: VolumeOptions(solve_rtol=0.5), "solve_rtol"),
    (lambda: MCOptions(photons=1), "photons"),
    (lambda: MCOptions(seed=-1), "seed"),
    (lambda: MCOptions(engine="gpu"), "engine"),
    (lambda: MCOptions(fast_interior="yes"), "fast_interior"),
    (lambda: CompareOptions(floor=2.0), "floor"),
    (lambda: CompareOptions(width=0), "width"),
    (lambda: CompareOptions(source_model=("point", "beam", "point")), "source model"),
])
def test_records_refuse_bad_values_where_they_are_made(make, needle):
    with pytest.raises(MeshshadeError, match=needle) as info:
        make()
    assert "\n" not in str(info.value)


def test_the_volume_options_are_honoured(sphere):
    """h0 forces the lattice's spacing; a tighter solve tolerance takes more iterations."""
    coarse = bake(sphere, SKIN, SUN, BakeOptions(volume=VolumeOptions(h0=2.0, solve_rtol=1e-2)))
    fine = bake(sphere, SKIN, SUN, BakeOptions(volume=VolumeOptions(h0=2.0, solve_rtol=1e-8)))
    assert coarse.stats["volume_resolution_mm"] == fine.stats["volume_resolution_mm"] == 2.0
    assert coarse.stats["volume_resolution_limited_by"] == "given"
    assert min(fine.stats["volume_solve_iterations"]) > max(coarse.stats["volume_solve_iterations"])
    assert np.abs(fine.radiance - coarse.radiance).max() > 0


def test_former_bake_keywords_warn_and_bake_the_same(sphere):
    new = bake(sphere, SKIN, SUN, BakeOptions(model="curved", surface=SurfaceOptions(transport="direct",
                                                                                      geodesic="arc")))
    with pytest.warns(DeprecationWarning, match=r"bake\(model=, transport=, geodesic=\.\.\.\) is deprecated"):
        old = bake(sphere, SKIN, SUN, model="curved", transport="direct", geodesic="arc")
    np.testing.assert_array_equal(old.radiance, new.radiance)
    with pytest.warns(DeprecationWarning, match="near_field"):   # the older alias of source_model as well
        beam = bake(sphere, SKIN, SUN, model="dipole", near_field="beam", transport="direct")
    assert beam.stats["near_field"] == "beam"
    with pytest.warns(DeprecationWarning), pytest.raises(ParameterError, match="disagree"):
        bake(sphere, SKIN, SUN, model="dipole", source_model="point", near_field="beam")
    with pytest.raises(TypeError, match="unexpected keyword argument 'colour'"):
        bake(sphere, SKIN, SUN, colour="red")


def test_a_built_transport_is_reused_and_the_former_keywords_say_so(sphere):
    first = bake(sphere, SKIN, SUN)
    again = bake(sphere, SKIN, SUN, reuse=first.volume)
    np.testing.assert_array_equal(again.radiance, first.radiance)
    with pytest.warns(DeprecationWarning, match=r"volume=<built transport>\) is deprecated; pass it as reuse="):
        old = bake(sphere, SKIN, SUN, volume=first.volume)
    np.testing.assert_array_equal(old.radiance, first.radiance)
    with pytest.warns(DeprecationWarning, match="volume_cache"):
        bake(sphere, SKIN, SUN, volume_cache=object())
    with pytest.raises(ParameterError, match="another mesh or material"):
        bake(sphere, Material.preset("marble"), SUN, reuse=first.volume)
    with pytest.raises(ParameterError, match="the model is not volume"):
        bake(sphere, SKIN, SUN, BakeOptions(model="dipole"), reuse=first.volume)
    core = SurfaceTransport.build(sphere, SKIN, "dipole")
    with pytest.warns(DeprecationWarning, match=r"transport=<built transport>"):
        old = bake(sphere, SKIN, SUN, BakeOptions(model="dipole"), transport=core)
    np.testing.assert_array_equal(old.radiance, bake(sphere, SKIN, SUN, BakeOptions(model="dipole"),
                                                     reuse=core).radiance)


def test_surface_transport_build_takes_the_record_and_the_former_keywords_warn(sphere):
    new = SurfaceTransport.build(sphere, SKIN, "auto", SurfaceOptions(geodesic="arc",
                                                                      auto=AutoTolerances(curvature_tol=np.inf)))
    with pytest.warns(DeprecationWarning, match=r"SurfaceTransport.build\(geodesic=, auto_options=\.\.\.\)"):
        old = SurfaceTransport.build(sphere, SKIN, "auto", geodesic="arc", auto_options={"curvature_tol": np.inf})
    assert np.array_equal(old.kind, new.kind) and old.stats == new.stats


def test_former_simulate_keywords_warn_and_walk_the_same(sphere):
    beam = [BeamLight((0.0, 0.0, 20.0), (0.0, 0.0, -1.0))]
    new = simulate(sphere, SKIN, beam, MCOptions(photons=2000, seed=5, beam_distances=False))
    with pytest.warns(DeprecationWarning, match=r"simulate\(photons=, seed=, beam_distances=\.\.\.\) is deprecated"):
        old = simulate(sphere, SKIN, beam, photons=2000, seed=5, beam_distances=False)
    np.testing.assert_array_equal(old.radiance, new.radiance)
    with pytest.raises(TypeError, match="unexpected keyword argument 'threads'"):
        simulate(sphere, SKIN, beam, threads=2)


def test_former_comparison_keywords_warn_and_compare_the_same(sphere):
    models = ("dipole", "curved")
    new = run_comparison(sphere, SKIN, SUN, models, CompareOptions(width=16, height=16, spp=1, floor=1e-2),
                         surface=SurfaceOptions(transport="direct", cutoff_tol=1e-3))
    with pytest.warns(DeprecationWarning, match=r"run_comparison\(width=, .*\) is deprecated") as record:
        old = run_comparison(sphere, SKIN, SUN, models, width=16, height=16, spp=1, floor=1e-2, transport="direct",
                             cutoff_tol=1e-3)
    assert len([w for w in record if w.category is DeprecationWarning]) == 1
    for a, b in zip(old["bakes"], new["bakes"]):
        np.testing.assert_array_equal(a.radiance, b.radiance)
    np.testing.assert_array_equal(old["images"][0][0], new["images"][0][0])
    assert old["stats"]["max_rel_diff"] == new["stats"]["max_rel_diff"]


def test_the_records_make_no_warning_of_their_own(sphere):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        bake(sphere, SKIN, SUN, BakeOptions(model="dipole", surface=SurfaceOptions(transport="direct")))
