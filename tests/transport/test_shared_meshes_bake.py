"""Bake the developers' real meshes (../shared/meshes) at realistic sizes: finite, non-negative, energy-bounded,
and the curved-vs-dipole difference concentrated where the surface is curved. Skips where ../shared is absent."""
import numpy as np
import pytest

from meshshade.geometry.mesh import Mesh
from meshshade.io import read_mesh_arrays
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.transport.baking import bake
from meshshade.transport import BakeOptions, SurfaceOptions

#: file -> realistic size of its largest extent in mm
SIZES = {"spot.obj": 120.0, "blub.obj": 150.0, "bob.obj": 100.0, "hand.obj": 180.0, "boot.obj": 280.0,
         "skull.obj": 200.0, "lee_perry_smith_head.obj": 200.0, "armadillo.obj": 150.0, "bunny.ply": 150.0}


def scaled(shared_meshes, name):
    V, F = read_mesh_arrays(shared_meshes / name)
    V = (V - V.mean(axis=0)) * (SIZES[name] / np.ptp(V, axis=0).max())
    return Mesh(V, F)


def check_bake(mesh, material, geodesic="exact", *, min_ratio=2.0, min_sign=0.85):
    light = DirectionalLight((0.3, -0.6, -0.75), 1.0)
    out = {m: bake(mesh, material, [light], BakeOptions(
        model=m, surface=SurfaceOptions(geodesic=geodesic))) for m in ("dipole", "curved")}
    entering = out["dipole"].samples.power.sum()
    for model, res in out.items():
        assert np.all(np.isfinite(res.radiance)) and np.all(res.radiance >= 0), model
        assert np.all((res.radiance * mesh.vertex_areas[:, None]).sum(axis=0) <= entering), model
    a, b = out["curved"].radiance[:, 0], out["dipole"].radiance[:, 0]
    H = 0.5 * (out["curved"].k1 + out["curved"].k2)
    samples = out["dipole"].samples
    direct = np.zeros(mesh.n_vertices, bool)  # directly lit vertices (elsewhere light arrives from afar)
    direct[samples.vertex[samples.vertex >= 0]] = True
    sel = direct & (b > 1e-3 * b.max())
    rel = a[sel] / b[sel] - 1
    h = H[sel]
    lo, mid, hi = np.quantile(np.abs(h), [0.25, 0.5, 0.75])
    # the curvature correction is concentrated where the surface is curved ...
    assert np.abs(rel[np.abs(h) >= hi]).mean() > min_ratio * np.abs(rel[np.abs(h) <= lo]).mean()
    # ... and raises convex, lowers concave regions (docs/physics.md §7.4: sign of the normal curvature)
    curved = np.abs(h) >= mid
    assert np.mean(np.sign(rel[curved]) == np.sign(h[curved])) > min_sign
    return rel


@pytest.mark.parametrize("geodesic", ["arc", pytest.param("exact", marks=pytest.mark.slow)])
def test_bake_shared_mesh_bob_curved_vs_dipole(shared_meshes, geodesic):
    """bob (5.3k vertices): the default suite bakes with the arc geodesics (4.7 s of CPU against 21.5 s with the
    exact ones, which stay in the slow set); measured ratio 4.58 and sign agreement 0.987 with arc, 4.70 and 0.988
    with exact, against the thresholds 2 and 0.85 of both."""
    check_bake(scaled(shared_meshes, "bob.obj"), Material.preset("skin1"), geodesic=geodesic)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SIZES))
def test_bake_every_shared_mesh(shared_meshes, name):
    # the fast "arc" geodesics keep the nine bakes (up to 50k vertices) within minutes; the properties checked
    # here (finite, non-negative, energy, where curvature matters) do not depend on the 1-11 % distance error
    # Scanned meshes carry curvature detail far below the transport length, so a vertex's own mean curvature
    # predicts the correction less well than on the smooth bob (measured there: 4.5x, 96 %). Measured on the nine
    # meshes (arc geodesics): quartile ratio >= 1.82 and sign agreement >= 0.75 (head scan 0.75, bunny 0.77);
    # the thresholds below sit under those minima and still fail for a correction unrelated to curvature
    # (ratio ~1, sign agreement ~0.5).
    check_bake(scaled(shared_meshes, name), Material.preset("skin1"), geodesic="arc", min_ratio=1.5, min_sign=0.7)
