"""Cut-cell P1 finite elements (meshshade/volume/cutfem.py, docs/physics.md eq. (99)) against references written
here.

* cut_tetrahedron, random tetrahedra and corner depths with 1, 2 and 3 positive corners and planes through a
  vertex, an edge or a face: the inside volume against the closed form vol{phi > 0} / vol = sum_{s_i > 0} s_i^3 /
  prod_{j != i} (s_i - s_j) (the divided difference of the truncated cube: the volume fraction of a linear
  function's super-level set on a simplex); the volume, int_in l_i, the cut area, int_cut l_i and int_cut l_i l_j
  against a twin that takes the inside as the convex hull of its corners (scipy's Qhull), cones it from its
  centroid into tetrahedra and the cut polygon into triangles sorted by angle, integrated with exact rules; and a
  Monte Carlo check of the volume and the first moments (1e6 points, 4 standard errors).
* assemble: a half-space below a tilted plane is resolved exactly (sum m and sum B equal the closed-form volume
  and area of the plane in the lattice's cubes to rounding, hanging nodes on the plane included); a ball converges
  at second order in both (measured 4.0 per halving); a box's volume at second order and its area at first order
  (the P1 interpolant of the distance bevels sharp edges: a limitation, measured numbers in the test); the mass
  gains exactly GHOST times the outside part of the cut tetrahedra; S annihilates constants; and Green's
  identity: for a linear u = a.x, (S u)_i = int_Gamma (n.a) phi_i dS + GHOST sum_T |T \\ Omega| grad phi_i . a,
  to rounding, with the cut surface, its normals and the constrained basis (hanging nodes the mean of their
  parents) computed by the twin. It holds exactly with the ghost term included (without it, (S u)_i differs by
  that term: checked non-zero), and with hanging nodes on cut cubes provided the cut surface is conforming there
  (the depth at a hanging node its parents' mean, like the field). The lattice as built keeps the surface's own
  depth at hanging nodes: the identity fails there (strict xfail, numbers in its reason).
"""
from __future__ import annotations

import copy
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.spatial import ConvexHull

from meshshade.volume.cutfem import GHOST, assemble, cut_tetrahedron
from meshshade.volume.lattice import Grading, build_lattice

_spec = importlib.util.spec_from_file_location("_volume_reference", Path(__file__).with_name("_volume_reference.py"))
ref = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ref)

#: Kuhn's six tetrahedra of a cube, from the definition: the paths 0 -> 7 raising one axis at a time, corner
#: (i, j, k) numbered i + 2 j + 4 k
KUHN = np.array([[0, 1 << a, (1 << a) | (1 << b), 7] for a in range(3) for b in range(3) if a != b])


# ------------------------------------------------------------------------------------------------ twins
def closed_form_fraction(s):
    """vol{sum l_i s_i > 0} / vol of a tetrahedron (distinct s)."""
    s = np.asarray(s, dtype=np.float64)
    out = 0.0
    for i in range(4):
        if s[i] > 0:
            out += s[i] ** 3 / np.prod([s[i] - s[j] for j in range(4) if j != i])
    return out


def _crossings(P, s):
    """Points (barycentric rows) where the linear function crosses zero on the edges (one end > 0, the other <= 0),
    as the code's convention puts a zero corner outside."""
    rows = []
    for i in range(4):
        for j in range(4):
            if s[i] > 0 >= s[j]:
                t = s[i] / (s[i] - s[j])
                b = np.zeros(4)
                b[i], b[j] = 1.0 - t, t
                rows.append(b)
    return np.array(rows)


def twin_cut(P, s):
    """(vol_in, m (4,), area, bm (4,), bb (4, 4)) of the tetrahedron P (4, 3) with corner depths s by the convex
    hull route (module docstring)."""
    P, s = np.asarray(P, dtype=np.float64), np.asarray(s, dtype=np.float64)
    vfull = abs(np.linalg.det(P[1:] - P[0])) / 6.0
    cross = _crossings(P, s)
    inside = np.eye(4)[s > 0]
    m = np.zeros(4)
    vol = 0.0
    pts_b = np.concatenate([inside, cross]) if cross.size else inside
    if pts_b.shape[0] >= 4:
        X = pts_b @ P
        try:
            hull = ConvexHull(X)
            vol = hull.volume
        except Exception:      # a flat inside (a plane through a face): no volume
            vol = 0.0
        if vol > 0:
            cb = pts_b.mean(axis=0)
            cx = cb @ P
            for simplex in hull.simplices:
                tb = np.concatenate([pts_b[simplex], cb[None]])
                v = abs(np.linalg.det(np.concatenate([X[simplex], cx[None]])[:3] - cx)) / 6.0
                m += v * tb.mean(axis=0)           # a linear function's integral: volume times the centroid value
    area, bm, bb = 0.0, np.zeros(4), np.zeros((4, 4))
    if cross.shape[0] >= 3:
        X = cross @ P
        c = X.mean(axis=0)
        nrm = np.cross(X[1] - X[0], X[2] - X[0])
        if np.linalg.norm(nrm) == 0 and X.shape[0] == 4:
            nrm = np.cross(X[1] - X[0], X[3] - X[0])
        if np.linalg.norm(nrm) > 0:
            e1 = (X[0] - c) / max(np.linalg.norm(X[0] - c), 1e-300)
            e2 = np.cross(nrm / np.linalg.norm(nrm), e1)
            order = np.argsort(np.arctan2((X - c) @ e2, (X - c) @ e1))
            B = cross[order]
            for k in range(1, B.shape[0] - 1):
                tri = B[[0, k, k + 1]]
                xt = tri @ P
                a = 0.5 * np.linalg.norm(np.cross(xt[1] - xt[0], xt[2] - xt[0]))
                area += a
                bm += a * tri.mean(axis=0)
                # the edge-midpoint rule is exact for quadratics on a triangle
                mids = 0.5 * (tri[[0, 1, 2]] + tri[[1, 2, 0]])
                bb += a / 3.0 * np.einsum("qi,qj->ij", mids, mids)
    return vol, m, area, bm, bb, vfull


def code_cut(P, s):
    m, bm, bb = np.zeros(4), np.zeros(4), np.zeros((4, 4))
    vin, vfull, area = cut_tetrahedron(np.ascontiguousarray(P, dtype=np.float64),
                                       np.ascontiguousarray(s, dtype=np.float64), m, bm, bb)
    return vin, m, area, bm, bb, vfull


def _random_cases(rng, n_pos, n=40):
    out = []
    while len(out) < n:
        P = rng.standard_normal((4, 3)) * rng.uniform(0.3, 3.0)
        if abs(np.linalg.det(P[1:] - P[0])) < 0.05:
            continue
        s = rng.uniform(0.05, 1.0, 4) * np.where(np.arange(4) < n_pos, 1.0, -1.0)
        out.append((P, rng.permutation(s)))
    return out


# ------------------------------------------------------------------------------------------------ cut_tetrahedron
@pytest.mark.parametrize("n_pos", [0, 1, 2, 3, 4])
def test_cut_tetrahedron_against_the_twins(n_pos, rng):
    for P, s in _random_cases(rng, n_pos):
        got, want = code_cut(P, s), twin_cut(P, s)
        vfull = want[5]
        assert got[5] == pytest.approx(vfull, rel=1e-13)
        assert got[0] == pytest.approx(closed_form_fraction(s) * vfull, rel=1e-10, abs=1e-14 * vfull)
        assert got[0] == pytest.approx(want[0], rel=1e-10, abs=1e-14 * vfull)
        np.testing.assert_allclose(got[1], want[1], rtol=1e-10, atol=1e-13 * vfull)
        scale = vfull ** (2.0 / 3.0)
        assert got[2] == pytest.approx(want[2], rel=1e-10, abs=1e-13 * scale)
        np.testing.assert_allclose(got[3], want[3], rtol=1e-10, atol=1e-13 * scale)
        np.testing.assert_allclose(got[4], want[4], rtol=1e-10, atol=1e-13 * scale)
        if n_pos in (0, 4):
            assert got[2] == 0.0 and got[0] == pytest.approx(vfull if n_pos == 4 else 0.0, rel=1e-14)


@pytest.mark.parametrize("s", [(0.0, 0.7, -0.4, -0.9), (0.0, 0.7, 0.4, -0.9), (0.0, 0.7, 0.4, 0.9),
                               (0.0, 0.0, 0.6, -0.5), (0.0, 0.0, 0.6, 0.5), (0.0, 0.0, 0.0, 0.8),
                               (0.0, 0.0, 0.0, -0.8), (0.0, -0.3, -0.6, -0.2)])
def test_cut_tetrahedron_through_vertices(s, rng):
    """Planes through one, two or three corners (a corner at depth 0 counts as outside): the twins' values, and
    the special cases in closed form: three zero corners and one inside corner is the whole tetrahedron with the
    opposite face as the cut surface; nothing positive is nothing."""
    P = np.array([[0.1, -0.2, 0.0], [1.3, 0.1, 0.2], [0.2, 1.1, -0.1], [0.3, 0.2, 1.4]])
    for perm in (np.arange(4), rng.permutation(4)):
        sp_ = np.asarray(s)[perm]
        got, want = code_cut(P, sp_), twin_cut(P, sp_)
        vfull = want[5]
        assert got[0] == pytest.approx(want[0], rel=1e-12, abs=1e-15)
        np.testing.assert_allclose(got[1], want[1], rtol=1e-12, atol=1e-15)
        assert got[2] == pytest.approx(want[2], rel=1e-12, abs=1e-15)
        np.testing.assert_allclose(got[3], want[3], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(got[4], want[4], rtol=1e-12, atol=1e-15)
        if sorted(s) == [0.0, 0.0, 0.0, 0.8]:
            face = P[sp_ == 0.0]
            assert got[0] == pytest.approx(vfull, rel=1e-14)
            assert got[2] == pytest.approx(0.5 * np.linalg.norm(np.cross(face[1] - face[0], face[2] - face[0])),
                                           rel=1e-14)
        if max(s) <= 0.0:
            assert got[0] == 0.0 and got[2] == 0.0


def test_cut_tetrahedron_against_monte_carlo():
    """Volume and int_in l_i by 1e6 uniform points of the tetrahedron (Dirichlet(1,1,1,1) barycentrics): within 4
    standard errors, for one case of each sign pattern."""
    rng = np.random.default_rng(11)
    P = np.array([[0.0, 0.0, 0.0], [2.0, 0.1, 0.0], [0.3, 1.5, 0.2], [0.1, 0.4, 1.8]])
    vfull = abs(np.linalg.det(P[1:] - P[0])) / 6.0
    lam = rng.dirichlet(np.ones(4), size=1_000_000)
    for s in ((0.9, -0.3, -0.5, -0.2), (0.9, 0.3, -0.5, -0.2), (0.9, 0.3, 0.5, -0.2)):
        got = code_cut(P, np.array(s))
        inside = lam @ np.array(s) > 0
        f = np.concatenate([inside[:, None], lam * inside[:, None]], axis=1) * vfull
        mean, se = f.mean(axis=0), f.std(axis=0) / math.sqrt(lam.shape[0])
        np.testing.assert_array_less(np.abs(np.concatenate([[got[0]], got[1]]) - mean), 4 * se + 1e-15)


# ------------------------------------------------------------------------------------------------ assembly twins
def constraint_matrix(lattice, asm):
    """(N, n) sparse: every lattice node's value from the unknowns: an unknown's node itself, a hanging node the
    mean of its parents (resolved recursively), other nodes 0. Built from lattice.hanging and parents only."""
    N, n = lattice.n_nodes, asm.n
    rows = {int(v): {k: 1.0} for k, v in enumerate(asm.free)}
    parent = {int(h): (int(p[0]), int(p[1])) for h, p in zip(lattice.hanging, lattice.parents)}

    def row(j, depth=0):
        if j in rows:
            return rows[j]
        if j not in parent or depth > 40:
            return {}
        out = {}
        for p in parent[j]:
            for k, w in row(p, depth + 1).items():
                out[k] = out.get(k, 0.0) + 0.5 * w
        rows[j] = out
        return out

    r, c, v = [], [], []
    for j in range(N):
        for k, w in row(j).items():
            r.append(j)
            c.append(k)
            v.append(w)
    return sp.csr_matrix((v, (r, c)), shape=(N, n))


def cut_tets(lattice):
    """(P (T, 4, 3), s (T, 4), node (T, 4)) of the Kuhn tetrahedra of every cube with a corner at depth <= 0."""
    cn = lattice.cell_nodes
    cut = np.any(lattice.depth[cn] <= 0.0, axis=1)
    nodes = cn[cut][:, KUHN].reshape(-1, 4)
    return lattice.nodes[nodes], lattice.depth[nodes], nodes


EDGES6 = [(i, j) for i in range(4) for j in range(i + 1, 4)]


def twin_flux(lattice, a, ghost):
    """Per lattice node j: sum over cut tetrahedra T of int_{Gamma cap T} l_j^T (n . a) dS + ghost |T \\ Omega|
    grad l_j^T . a, n the outward normal (-grad depth / |grad depth|); and the total of |T \\ Omega| over the
    tetrahedra with something inside (mm^3). Vectorised over the tetrahedra: the cut polygon from the edges'
    crossings sorted by angle about their centroid, fanned into triangles (centroid rule: exact for linear
    integrands); the inside volume by closed_form_fraction (twin_cut where two corner depths coincide)."""
    P, s, nodes = cut_tets(lattice)
    T = P.shape[0]
    E = P[:, 1:] - P[:, :1]
    vfull = np.abs(np.linalg.det(E)) / 6.0
    Ginv = np.linalg.inv(E)               # E Ginv = I: column c of Ginv is the gradient of l_{c+1}
    grads = np.concatenate([-Ginv.sum(axis=2)[:, None, :], np.transpose(Ginv, (0, 2, 1))], axis=1)   # (T, 4, 3)
    grad_depth = np.einsum("tk,tkd->td", s, grads)
    # crossings: an edge with one end > 0 and the other <= 0
    pts_b = np.zeros((T, 6, 4))
    valid = np.zeros((T, 6), dtype=bool)
    for e, (i, j) in enumerate(EDGES6):
        pos_i, pos_j = s[:, i] > 0, s[:, j] > 0
        ok = pos_i != pos_j
        t = np.where(ok, s[:, i] / np.where(ok, s[:, i] - s[:, j], 1.0), 0.0)
        pts_b[:, e, i] = 1.0 - t
        pts_b[:, e, j] = t
        valid[:, e] = ok
    X = np.einsum("tek,tkd->ted", pts_b, P)
    cnt = valid.sum(axis=1)
    cen = np.where(cnt[:, None] > 0, np.einsum("te,ted->td", valid, X) / np.maximum(cnt, 1)[:, None], 0.0)
    nrm = np.where(np.linalg.norm(grad_depth, axis=1)[:, None] > 0, grad_depth, 1.0)
    nrm = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    ref_dir = np.where(np.abs(nrm[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    e1 = np.cross(nrm, ref_dir)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(nrm, e1)
    rel = X - cen[:, None, :]
    ang = np.arctan2(np.einsum("ted,td->te", rel, e2), np.einsum("ted,td->te", rel, e1))
    order = np.argsort(np.where(valid, ang, np.inf), axis=1)
    Xs = np.take_along_axis(X, order[:, :, None], axis=1)
    Bs = np.take_along_axis(pts_b, order[:, :, None], axis=1)
    bm = np.zeros((T, 4))
    area = np.zeros(T)
    for k in (1, 2):
        has = cnt >= k + 2
        tri_area = 0.5 * np.linalg.norm(np.cross(Xs[:, k] - Xs[:, 0], Xs[:, k + 1] - Xs[:, 0]), axis=1) * has
        area += tri_area
        bm += tri_area[:, None] * (Bs[:, 0] + Bs[:, k] + Bs[:, k + 1]) / 3.0
    n_out = -nrm
    out = np.zeros(lattice.n_nodes)
    np.add.at(out, nodes.ravel(), (bm * (n_out @ a)[:, None]).ravel())
    # inside volume
    vin = np.empty(T)
    gap = np.abs(s[:, :, None] - s[:, None, :]) + np.eye(4) * 1e300
    close = np.any((s[:, :, None] > 0) & (gap < 1e-6 * np.abs(s).max(axis=1)[:, None, None]), axis=(1, 2))
    for t in range(T):
        vin[t] = twin_cut(P[t], s[t])[0] if close[t] else closed_form_fraction(s[t]) * vfull[t]
    active = (vin > 0) | (area > 0)
    outside = np.where(active, vfull - vin, 0.0)
    np.add.at(out, nodes.ravel(), (ghost * outside[:, None] * np.einsum("tkd,d->tk", grads, a)).ravel())
    return out, float(outside.sum())


def _csr(asm, data):
    return sp.csr_matrix((data, asm.indices, asm.indptr), shape=(asm.n, asm.n))


# ------------------------------------------------------------------------------------------------ assembly
@pytest.fixture(scope="module")
def graded_ball():
    """A ball of radius 3.1 mm, h0 = 0.45 mm, level 0 on part of the surface only (``refine``), so hanging nodes
    lie on cut cubes: (lattice, assembly with GHOST, assembly with ghost 0)."""
    c = np.array([0.17, -0.29, 0.11])
    g = Grading(0.45, (0.0, 0.5, 0.5 + math.sqrt(3.0) * 0.9), 50.0)
    lat = build_lattice(ref.ball_depth(c, 3.1), c - 3.1, c + 3.1, g, refine=lambda x: x[:, 0] > c[0] + 0.4)
    assert np.bincount(lat.level, minlength=2)[:2].min() > 0 and lat.hanging.size > 0
    return lat, assemble(lat), assemble(lat, ghost=0.0), c


def half_space_volume_and_area(normal, offset, lo, h):
    """Closed forms for the cubes lo + [0, h]^3 (lo (C, 3), h (C,)) cut by {n . x < offset} (unit n, no zero
    component): with the axes of negative n_i reflected (x_i -> h - x_i, so a = |n| > 0 and the offset grows by
    h sum |n_i| over them), vol = sum_v (-1)^|v| (b - h a.v)_+^3 / (6 a1 a2 a3) over the cube's corners v (the
    simplex {a.x < b} of the orthant, inclusion-exclusion over the cube's faces), and the plane's area in the cube
    |n| d vol / d b."""
    n = np.asarray(normal, dtype=np.float64)
    a = np.abs(n)
    b = offset - lo @ n + h * np.sum(a[n < 0])
    vol = np.zeros(lo.shape[0])
    dvol = np.zeros(lo.shape[0])
    for v in np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)]):
        x = np.maximum(b - h * (a @ v), 0.0)
        sign = (-1.0) ** v.sum()
        vol += sign * x ** 3
        dvol += sign * 3.0 * x ** 2
    return vol / (6.0 * np.prod(a)), dvol / (6.0 * np.prod(a))


def test_a_tilted_half_space_is_exact():
    """The half-space below a tilted plane (a linear depth: the cut is exact) on a lattice with level 0 on part of
    the plane (hanging nodes on cut cubes, where the linear depth is conforming): sum m = the cubes' volume below
    the plane and sum B = the plane's area within them, to rounding, against the closed forms."""
    n = np.array([0.31, -0.42, 0.85])
    n /= np.linalg.norm(n)
    b = 0.137

    def depth(p, bound, **_):
        return np.clip(b - p @ n, -bound, bound)
    lo, hi = np.array([-3.0, -2.5, -2.0]), np.array([3.0, 2.5, 1.0])
    g = Grading(0.3, (0.0, 0.5, 0.5 + math.sqrt(3.0) * 0.6), 3.0)
    lat = build_lattice(depth, lo, hi, g, refine=lambda x: x[:, 0] > 0.2)
    assert np.bincount(lat.level, minlength=2)[:2].min() > 0
    cut = np.any(lat.depth[lat.cell_nodes] <= 0, axis=1)
    assert lat.hanging.size and np.isin(lat.cell_nodes[cut], lat.hanging).any()
    h = lat.cell_size
    vol, area = half_space_volume_and_area(n, b, lat.ijk * h[:, None], h)
    for ghost in (0.0, GHOST):
        asm = assemble(lat, ghost=ghost)
        assert asm.volume == pytest.approx(vol.sum(), rel=1e-12)
        assert asm.area == pytest.approx(area.sum(), rel=1e-12)
        assert _csr(asm, asm.b_data).sum() == pytest.approx(area.sum(), rel=1e-12)
        if ghost == 0.0:
            assert asm.m.sum() == pytest.approx(vol.sum(), rel=1e-12)


def test_ball_volume_and_area_converge_at_second_order():
    """A ball of radius 4.3 mm at h0 = 0.5 and 0.25 mm: the discrete ball lies inside the sphere and its volume
    error is at most 9 h^2 / (8 R^2) (|x| is convex, so its P1 interpolant lies above it by at most lambda rho^2 / 2,
    lambda = 1 / R its Hessian's largest eigenvalue and rho = sqrt(3) h / 2 the Kuhn tetrahedra's circumradius: the
    surface moves in by at most 3 h^2 / (8R), a relative volume of 3 / R times that); volume and area errors
    shrink by 4 per halving (measured: volume -0.67, -0.17 %, area -0.35, -0.087 %;
    orders 2.00)."""
    R, c = 4.3, np.array([0.13, 0.31, -0.07])
    errs = []
    for h0 in (0.5, 0.25):
        lat = build_lattice(ref.ball_depth(c, R), c - R, c + R, Grading(h0, (0.0, 1.0, 3.0), 50.0))
        asm = assemble(lat, ghost=0.0)
        assert asm.m.sum() == pytest.approx(asm.volume, rel=1e-12)
        assert _csr(asm, asm.b_data).sum() == pytest.approx(asm.area, rel=1e-12)
        ev = asm.volume / (4.0 / 3.0 * math.pi * R ** 3) - 1.0
        ea = asm.area / (4.0 * math.pi * R * R) - 1.0
        assert -9.0 * h0 * h0 / (8.0 * R * R) < ev < 0, (h0, ev)
        assert ea < 0, (h0, ea)
        errs.append((ev, ea))
    for k in range(2):
        order = math.log2(errs[0][k] / errs[1][k])
        assert 1.8 < order < 2.2, (k, errs)


def test_box_volume_is_second_order_and_its_area_first_order():
    """A 3.22 x 2.63 x 2.14 mm box off the lattice's planes at h0 = 0.5, 0.25, 0.125 mm: the volume converges at
    second order (measured -6.4, -1.8, -0.50 %: orders 1.84, 1.86), the area only at first order (-11.1, -5.8,
    -2.9 %: orders 0.93, 1.02): the P1 interpolant of the distance bevels every sharp edge over a cell, so the
    Robin boundary misses about (2 - sqrt(2)) h per unit length of edge (a limitation of interpolating the
    signed distance, not a bug of the integration: the faces themselves are exact, see the tilted half-space)."""
    lo, hi = np.array([-1.13, -0.52, 0.27]), np.array([2.09, 2.11, 2.41])
    e = hi - lo
    vol, area = np.prod(e), 2 * (e[0] * e[1] + e[0] * e[2] + e[1] * e[2])
    errs = []
    for h0 in (0.5, 0.25, 0.125):
        lat = build_lattice(ref.box_depth(lo, hi), lo, hi, Grading(h0, (0.0, 0.5, 0.5 + math.sqrt(3) * 2 * h0), 50.0))
        asm = assemble(lat, ghost=0.0)
        errs.append((asm.volume / vol - 1.0, asm.area / area - 1.0))
    errs = np.array(errs)
    assert np.all(errs < 0)
    order = np.log2(errs[:-1] / errs[1:])
    assert np.all(order[:, 0] > 1.7), order
    assert np.all((order[:, 1] > 0.8) & (order[:, 1] < 1.2)), order


def test_ghost_mass_is_the_outside_part_of_the_cut_tetrahedra(graded_ball):
    lat, asm, asm0, _ = graded_ball
    _, outside = twin_flux(lat, np.zeros(3), 0.0)
    assert asm0.m.sum() == pytest.approx(asm0.volume, rel=1e-12)
    assert asm.m.sum() - asm0.m.sum() == pytest.approx(GHOST * outside, rel=1e-9)
    assert asm.volume == asm0.volume and asm.area == asm0.area
    np.testing.assert_array_equal(asm.b_data, asm0.b_data)


def test_matrices_are_symmetric_and_annihilate_constants(graded_ball):
    lat, asm, asm0, _ = graded_ball
    for a in (asm, asm0):
        S, B = _csr(a, a.s_data), _csr(a, a.b_data)
        assert abs(S - S.T).max() <= 1e-15 * abs(S).max()
        assert abs(B - B.T).max() <= 1e-15 * abs(B).max()
        one = np.ones(a.n)
        assert np.abs(S @ one).max() < 1e-13 * abs(S).max()
        assert np.all(a.m >= 0) and np.all(B.diagonal() >= 0)


def green_residual(lat, ghost):
    """(max |(S u)_i - twin_i|, max |(S u)_i|, the twin without its ghost term) for u = a.x + 0.8."""
    A = assemble(lat, ghost=ghost)
    a = np.array([0.6, -1.1, 0.35])
    Su = _csr(A, A.s_data) @ (lat.nodes[A.free] @ a + 0.8)
    C = constraint_matrix(lat, A)
    want = C.T @ twin_flux(lat, a, ghost)[0]
    plain = C.T @ twin_flux(lat, a, 0.0)[0]
    return np.abs(Su - want).max(), np.abs(Su).max(), np.abs(Su - plain).max()


def conforming_copy(lat):
    """The lattice with each hanging node's depth replaced by the mean of its parents' (the coarse cube's P1 trace,
    as for the field): the cut surface then meets itself across level transitions."""
    out = copy.copy(lat)
    d = lat.depth.copy()
    for _ in range(32):
        new = 0.5 * (d[lat.parents[:, 0]] + d[lat.parents[:, 1]])
        if np.array_equal(new, d[lat.hanging]):
            break
        d[lat.hanging] = new
    out.depth = d
    return out


@pytest.mark.parametrize("ghost", [0.0, GHOST])
def test_greens_identity_with_depth_grading(ghost):
    """A ball graded with depth only (hanging nodes deep inside): (S u)_i equals the twin's boundary flux plus its
    ghost term to rounding; without the ghost term it would not (so the ghost is part of what is checked)."""
    c = np.array([0.17, -0.29, 0.11])
    g = Grading(0.45, (0.0, 0.5, 0.5 + math.sqrt(3.0) * 0.9), 50.0)
    lat = build_lattice(ref.ball_depth(c, 3.1), c - 3.1, c + 3.1, g)
    assert lat.hanging.size
    err, scale, without_ghost = green_residual(lat, ghost)
    assert err < 1e-12 * scale, err / scale
    if ghost:
        assert without_ghost > 1e-6 * scale


@pytest.mark.parametrize("ghost", [0.0, GHOST])
def test_greens_identity_with_hanging_nodes_on_the_surface(graded_ball, ghost):
    """The ball with level 0 on part of its surface, hanging nodes on cut cubes, with their depths conforming
    (conforming_copy): the identity holds to rounding, so the assembly's elimination of hanging nodes is exact."""
    lat = conforming_copy(graded_ball[0])
    cut = np.any(lat.depth[lat.cell_nodes] <= 0, axis=1)
    assert np.isin(lat.cell_nodes[cut], lat.hanging).any()
    err, scale, _ = green_residual(lat, ghost)
    assert err < 1e-12 * scale, err / scale


@pytest.mark.xfail(strict=True, reason="the depth at a hanging node is the surface's own, not its parents' mean: "
                   "where level 0 meets level 1 on the surface the fine and coarse cubes' cut surfaces do not meet "
                   "(a crack or overlap on their shared face; here the hanging depths differ from the parents' "
                   "mean by up to 0.25 mm), so 48 of 893 rows miss Green's identity by up to 0.019 of the largest "
                   "row (62 % of their own value)")
def test_greens_identity_on_the_lattice_as_built(graded_ball):
    err, scale, _ = green_residual(graded_ball[0], 0.0)
    assert err < 1e-12 * scale, err / scale
