"""Independent references and twins for the tests of meshshade.volume (loaded by path, like
tests/surface/_sphere_reference.py; nothing here imports the code under test).

* The Robin ball (docs/physics.md eq. (94)): the exitance on a ball of radius R with the boundary phi + 2 A D
  d phi / dn = 0 for a unit isotropic point source at radius r' (angle gamma between the source's and the
  receiver's directions),

      M(gamma) = kappa beta / (4 pi D x^2) sum_l (2l + 1) P_l(cos gamma) i_l(kappa r') / (i_l(x) + beta i_l'(x)) / (2A),

  x = kappa R, beta = 2 A D kappa, i_l the modified spherical Bessel functions, i_l' = i_{l+1} + (l / x) i_l.
  :func:`ball_exitance` writes i_l(z) = z^l / (2l + 1)!! 0F1(; l + 3/2; z^2 / 4) so that only ratios of 0F1 and
  (r' / R)^l appear (no Bessel function formed: no overflow or underflow for thousands of terms);
  :func:`ball_exitance_mpmath` is the same series with i_l from mpmath's besseli at 30 digits, and
  :func:`ball_centre_exitance` the closed form for a source at the centre (only l = 0), from the radial solution
  phi = (exp(-kappa r) + C sinh(kappa r)) / (4 pi D r) with C fixed by the Robin condition.
* Signed distances (positive inside) of a ball and of a box, written here, for lattices built without a mesh.
* Twins of the lattice's P1 space: the Kuhn tetrahedron of a point in a cube and its barycentrics
  (:func:`kuhn_barycentrics`), and a dense map of level-0 cells to the cube covering them (:func:`cell_grid`).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.special import hyp0f1


# ------------------------------------------------------------------------------------------------ the Robin ball
def bessel_ratio(l, r, kappa, beta, radius):
    """(L, S): i_l(kappa r) / (i_l(x) + beta i_l'(x)), x = kappa radius, by the 0F1 form (module docstring):
    the common factor kappa^l / (2l + 1)!! cancels, i_{l+1}(x) / i_l-part gives x / (2l + 3) 0F1(; l + 5/2)."""
    l = np.asarray(l, dtype=np.float64)[:, None]
    r = np.asarray(r, dtype=np.float64)[None, :]
    x = kappa * radius
    num = np.exp(l * np.log(r / radius)) * hyp0f1(l + 1.5, (kappa * r) ** 2 / 4.0)
    den = (hyp0f1(l + 1.5, x * x / 4.0) * (1.0 + beta * l / x)
           + beta * x / (2.0 * l + 3.0) * hyp0f1(l + 2.5, x * x / 4.0))
    return num / den


def ball_exitance(cos_gamma, r_source, *, D, sigma_a, A, radius, terms=None):
    """Eq. (94) at the points of the sphere at cos(gamma) from unit point sources at radius ``r_source`` (arrays
    broadcast together; r_source < radius). ``terms`` defaults to what makes (r'/R)^l below 1e-17; the last
    term is asserted negligible."""
    kappa = math.sqrt(sigma_a / D)
    x, beta = kappa * radius, 2.0 * A * D * kappa
    c, r = np.broadcast_arrays(np.asarray(cos_gamma, dtype=np.float64), np.asarray(r_source, dtype=np.float64))
    shape = c.shape
    c, r = c.ravel(), r.ravel()
    ru, inv = np.unique(r, return_inverse=True)
    if terms is None:
        terms = int(math.log(1e-17) / math.log(max(float(ru.max()), 1e-3 * radius) / radius)) + 40
    out = np.zeros_like(c)
    p_prev, p = np.ones_like(c), c.copy()
    last = None
    for start in range(0, terms, 200):
        ls = np.arange(start, min(terms, start + 200))
        G = bessel_ratio(ls, ru, kappa, beta, radius)[:, inv]
        for k, l in enumerate(ls):
            if l == 0:
                pl = p_prev
            elif l == 1:
                pl = p
            else:
                p_prev, p = p, ((2 * l - 1) * c * p - (l - 1) * p_prev) / l
                pl = p
            out += (2 * l + 1) * G[k] * pl
        last = G[-1]
    first = bessel_ratio([0], ru, kappa, beta, radius)[0, inv]
    assert np.all(np.abs(last) * 2 * terms < 1e-13 * np.abs(first)), "the ball series has not converged"
    return (kappa * beta / (4 * math.pi * D * x * x) * out / (2.0 * A)).reshape(shape)


def ball_exitance_mpmath(gamma, r_source, *, D, sigma_a, A, radius, terms=220, dps=30):
    """Eq. (94) with i_l(z) = sqrt(pi / (2z)) I_{l+1/2}(z) from mpmath at ``dps`` digits (the route of the old
    test_volume_fem): a source on the axis, receivers at the angles ``gamma``."""
    import mpmath as mp

    with mp.workdps(dps):
        kappa = mp.sqrt(mp.mpf(sigma_a) / mp.mpf(D))
        x, beta, y = kappa * radius, 2 * mp.mpf(A) * mp.mpf(D) * kappa, kappa * r_source

        def i_l(l, z):
            return mp.sqrt(mp.pi / (2 * z)) * mp.besseli(l + mp.mpf(1) / 2, z)

        coef = [(2 * l + 1) * i_l(l, y) / (i_l(l, x) + beta * (i_l(l + 1, x) + l / x * i_l(l, x)))
                for l in range(terms)]
        assert abs(coef[-1]) < mp.mpf(10) ** -14 * abs(coef[0])
        out = []
        for g in np.atleast_1d(gamma):
            cg = mp.cos(mp.mpf(float(g)))
            out.append(float(kappa * beta / (4 * mp.pi * D * x * x)
                             * mp.fsum(coef[l] * mp.legendre(l, cg) for l in range(terms)) / (2 * A)))
    return np.array(out)


def ball_centre_exitance(*, D, sigma_a, A, radius):
    """Closed form for a unit source at the ball's centre: phi(r) = (exp(-kappa r) + C sinh(kappa r)) / (4 pi D r)
    (the free-space Green's function plus the regular radial solution), C from phi(R) + 2 A D phi'(R) = 0;
    M = phi(R) / (2A), uniform over the sphere."""
    k, R, ell = math.sqrt(sigma_a / D), radius, 2.0 * A * D

    def parts(f, fp):
        # g(r) = f(r) / r: g + ell g' at R = f / R + ell (f' R - f) / R^2
        return f / R + ell * (fp * R - f) / (R * R)

    free = parts(math.exp(-k * R), -k * math.exp(-k * R))
    regular = parts(math.sinh(k * R), k * math.cosh(k * R))
    C = -free / regular
    phi = (math.exp(-k * R) + C * math.sinh(k * R)) / (4.0 * math.pi * D * R)
    return phi / (2.0 * A)


# ------------------------------------------------------------------------------------------------ shapes
def ball_depth(centre, radius):
    """depth(points, bound, **_) of a ball: radius - |p - centre|, clipped to +-bound (exact signed distance)."""
    c = np.asarray(centre, dtype=np.float64)

    def depth(points, bound, **_):
        return np.clip(radius - np.linalg.norm(np.asarray(points) - c, axis=1), -bound, bound)
    return depth


def box_depth(lo, hi):
    """depth(points, bound, **_) of the box lo..hi: the exact signed distance (inside: to the nearest face;
    outside: the length of the excess), clipped to +-bound."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    c, half = 0.5 * (lo + hi), 0.5 * (hi - lo)

    def depth(points, bound, **_):
        q = np.abs(np.asarray(points) - c) - half
        inside = np.all(q <= 0.0, axis=1)
        d = np.where(inside, -np.max(q, axis=1), -np.linalg.norm(np.maximum(q, 0.0), axis=1))
        return np.clip(d, -bound, bound)
    return depth


# ------------------------------------------------------------------------------------------------ P1 twins
def kuhn_barycentrics(u):
    """(corners (p, 4) in 0..7 (index i + 2j + 4k), weights (p, 4)) of local cube coordinates ``u`` (p, 3) in
    [0, 1]^3: the Kuhn tetrahedron is the path 0 -> 7 that raises the coordinates in decreasing order of size,
    and the weights are the successive differences of the sorted coordinates (1 - u_(1), u_(1) - u_(2),
    u_(2) - u_(3), u_(3)). Written from the definition, independently of lattice.locate_points."""
    u = np.asarray(u, dtype=np.float64)
    order = np.argsort(-u, axis=1, kind="stable")
    s = np.take_along_axis(u, order, axis=1)
    w = np.stack([1.0 - s[:, 0], s[:, 0] - s[:, 1], s[:, 1] - s[:, 2], s[:, 2]], axis=1)
    bit = 1 << order
    c1 = bit[:, 0]
    c2 = c1 | bit[:, 1]
    corners = np.stack([np.zeros_like(c1), c1, c2, np.full_like(c1, 7)], axis=1)
    return corners, w


def eval_in_cube(lattice, cube, values, points):
    """The P1 function with nodal ``values`` (N,) evaluated at ``points`` (p, 3) by the Kuhn tetrahedra of the
    given ``cube`` (p,) (a point on the cube's boundary is evaluated from that cube's side)."""
    h = lattice.grading.h0 * np.exp2(lattice.level[cube].astype(np.float64))
    u = np.clip(np.asarray(points) / h[:, None] - lattice.ijk[cube], 0.0, 1.0)
    corners, w = kuhn_barycentrics(u)
    nodes = np.take_along_axis(lattice.cell_nodes[cube], corners, axis=1)
    return np.sum(w * values[nodes], axis=1)


def cell_grid(level, ijk):
    """(grid (nx, ny, nz) int64: the cube covering each level-0 cell, -1 none; origin (3,)); also asserts that no
    level-0 cell is covered twice (the cubes of an octree partition do not overlap)."""
    scale = np.left_shift(1, level)[:, None]
    lo = ijk * scale
    hi = (ijk + 1) * scale
    origin = lo.min(axis=0)
    shape = tuple(int(x) for x in hi.max(axis=0) - origin)
    grid = np.full(shape, -1, dtype=np.int64)
    count = np.zeros(shape, dtype=np.int64)
    for c in range(level.size):
        a, b = lo[c] - origin, hi[c] - origin
        grid[a[0]:b[0], a[1]:b[1], a[2]:b[2]] = c
        count[a[0]:b[0], a[1]:b[1], a[2]:b[2]] += 1
    assert count.max() <= 1, "cubes overlap"
    return grid, origin


def neighbour_pairs(grid):
    """(a, b) cube indices of every pair of distinct cubes whose closed boxes touch (face, edge or corner), from the
    26-neighbourhood of the level-0 cells (both orders not repeated)."""
    pairs = []
    n = grid.shape
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dz in (-1, 0, 1):
                if (dx, dy, dz) <= (0, 0, 0):
                    continue
                a = grid[max(0, -dx):n[0] - max(0, dx), max(0, -dy):n[1] - max(0, dy), max(0, -dz):n[2] - max(0, dz)]
                b = grid[max(0, dx):n[0] - max(0, -dx), max(0, dy):n[1] - max(0, -dy), max(0, dz):n[2] - max(0, -dz)]
                ok = (a >= 0) & (b >= 0) & (a != b)
                pairs.append(np.stack([a[ok], b[ok]], axis=1))
    p = np.concatenate(pairs)
    p = np.sort(p, axis=1)
    return np.unique(p, axis=0)
