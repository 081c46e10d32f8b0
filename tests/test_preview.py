"""Notebook previews: readable reprs of results and ``.plot(mesh)`` (meshshade.preview)."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402

from meshshade import Material  # noqa: E402
from meshshade.errors import ParameterError  # noqa: E402
from meshshade.geometry.mesh import Mesh  # noqa: E402
from meshshade.geometry.procedural import icosphere  # noqa: E402
from meshshade.light import DirectionalLight  # noqa: E402
from meshshade.montecarlo import simulate  # noqa: E402
from meshshade.preview import mesh_preview, preview_colours  # noqa: E402
from meshshade.transport import bake  # noqa: E402
from meshshade.montecarlo import MCOptions
from meshshade.transport import BakeOptions, SurfaceOptions

MESH = Mesh(*icosphere(10.0, 2))
SUN = [DirectionalLight((0.0, 0.0, -1.0), 1.0)]


@pytest.fixture(scope="module")
def baked():
    return bake(MESH, Material.preset("skin1"), SUN, BakeOptions(
        model="dipole", surface=SurfaceOptions(transport="direct")))


def test_reprs_say_what_a_result_is(baked):
    text = repr(baked)
    assert text.startswith("<BakeResult dipole, skin1: 162 vertices") and "direct transport" in text
    assert "\n" not in text and len(text) < 200
    mc = simulate(MESH, Material.preset("skin1"), SUN, MCOptions(photons=2000, seed=1))
    text = repr(mc)
    assert text.startswith("<MCResult skin1: 2000 photons") and "diffuse reflectance" in text and len(text) < 200


def test_plot_colours_each_face_by_its_vertices(baked):
    fig = baked.plot(MESH)
    ax = fig.axes[0]
    polys = [c for c in ax.collections if isinstance(c, Poly3DCollection)]
    assert len(polys) == 1 and ax.get_title() == "dipole, skin1"
    expected = preview_colours(baked.radiance)[MESH.faces].mean(axis=1)
    rows = lambda a: a[np.lexsort(a.T[::-1])]  # noqa: E731 - matplotlib keeps the faces in depth order
    np.testing.assert_allclose(rows(polys[0].get_facecolor()[:, :3]), rows(expected), atol=1e-6)
    top = MESH.faces[MESH.vertices[MESH.faces].mean(axis=1)[:, 2].argmax()]
    bottom = MESH.faces[MESH.vertices[MESH.faces].mean(axis=1)[:, 2].argmin()]
    assert expected[np.all(MESH.faces == top, axis=1)][0, 0] > expected[np.all(MESH.faces == bottom, axis=1)][0, 0]


def test_preview_colours_exposure_and_bad_values():
    rad = np.outer(np.linspace(0.0, 1.0, 101), [1.0, 1.0, 1.0])
    c = preview_colours(rad)
    # the 99th percentile of the lit values (0.01 ... 1) is 0.9901: it and all above map to white
    assert c[0].tolist() == [0.0, 0.0, 0.0] and np.allclose(c[-1], 1.0, atol=1e-12) and np.all(c[-2] > 0.9999)
    assert np.all(np.diff(c[:, 0]) >= 0)
    bad = preview_colours(np.array([[np.nan, -1.0, np.inf], [1.0, 1.0, 1.0]]))
    assert bad[0].tolist() == [0.0, 0.0, 0.0]


def test_plot_refuses_another_mesh_and_thins_large_ones(baked):
    with pytest.raises(ParameterError, match="pass the mesh that was baked"):
        baked.plot(Mesh(*icosphere(10.0, 3)))
    fig = mesh_preview(MESH.vertices, MESH.faces, baked.radiance, title="t", max_faces=50)
    assert fig.axes[0].get_title() == "t (50 of 320 faces)"
