"""Sources along the refracted light (docs/physics.md eq. (95)): the Gauss-Laguerre line against its exact moments,
and a volume solve with them against the closed-form total of an exponential
line source under the half-space (eq. (93) integrated over depth)."""
from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from meshshade.volume import DiffusionOperator, locate_points, point_source_vector
from meshshade.volume.sources import line_sources
from meshshade.volume.tetmesh import box_tetrahedra, graded_axis

_spec = importlib.util.spec_from_file_location("volume_fem_tests", Path(__file__).with_name("test_volume_fem.py"))
fem_tests = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fem_tests)


@pytest.mark.parametrize("n_points", [1, 3, 6])
def test_line_sources_moments(n_points):
    """Power alpha' P per entry; the mean and, from two points on, the second moment of the depth are those of the
    exponential line, 1/sigma_t' and 2/sigma_t'^2."""
    st, a = 1.4, 0.93
    pos = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]])
    w = np.array([[0.0, 0.0, -1.0], [0.6, 0.0, -0.8]])
    pts, pw = line_sources(pos, w, np.array([2.0, 0.5]), sigma_t_prime=st, albedo_prime=a, n_points=n_points)
    pts, pw = pts.reshape(2, n_points, 3), pw.reshape(2, n_points)
    np.testing.assert_allclose(pw.sum(axis=1), a * np.array([2.0, 0.5]), rtol=1e-13)
    t = np.einsum("kjc,kc->kj", pts - pos[:, None], w)
    np.testing.assert_allclose(np.linalg.norm(pts - pos[:, None] - t[..., None] * w[:, None], axis=2), 0.0,
                               atol=1e-13)
    np.testing.assert_allclose((pw * t).sum(axis=1) / pw.sum(axis=1), 1.0 / st, rtol=1e-12)
    if n_points >= 2:
        np.testing.assert_allclose((pw * t ** 2).sum(axis=1) / pw.sum(axis=1), 2.0 / st ** 2, rtol=1e-12)


def test_line_source_total_under_the_half_space():
    """A graded block, 4-point line source under normal incidence: the exitance through the top within 0.2 % of
    alpha' sigma_t' / ((sigma_t' + sigma_tr)(1 + 2 A D sigma_tr)), where one point at 1/sigma_t' is 5.6 % low in
    exact arithmetic for this medium."""
    sp, sa, A, D = fem_tests.SIGMA_S_PRIME, fem_tests.SIGMA_A, fem_tests.A, fem_tests.D
    st, s_tr = sp + sa, fem_tests.SIGMA_TR
    a = sp / st
    total = a * st / ((st + s_tr) * (1.0 + 2.0 * A * D * s_tr))
    ax = graded_axis(-16.0, 16.0, 0.0, 0.4, 1.3)
    az = graded_axis(-16.0, 0.0, 0.0, 0.2, 1.3)
    nodes, tets = box_tetrahedra(ax, ax, az)
    op = DiffusionOperator(nodes, tets, D=D, sigma_a=sa, A=A)
    pts, pw = line_sources(np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, 0.0, -1.0]]), np.array([1.0]),
                           sigma_t_prime=st, albedo_prime=a, n_points=4)
    tet, bary = locate_points(nodes, tets, pts)
    M = op.solve(point_source_vector(nodes.shape[0], tets, tet, bary, pw)) / (2.0 * A)
    f = op.faces[np.all(np.isclose(nodes[op.faces][:, :, 2], 0.0), axis=1)]
    p0, p1, p2 = nodes[f[:, 0]], nodes[f[:, 1]], nodes[f[:, 2]]
    top = np.sum(0.5 * np.linalg.norm(np.cross(p1 - p0, p2 - p0), axis=1) * M[f].mean(axis=1))
    assert abs(top / total - 1.0) < 2e-3, (top, total)
    one_point = a * math.exp(-s_tr / st) / (1.0 + 2.0 * A * D * s_tr)
    assert one_point / total - 1.0 < -0.05
