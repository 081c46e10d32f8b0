"""The one evaluation of every bake model's kernel R(x_o; x_i) for a pair, compiled, behind one parameter record.

Every path of the bake evaluates its kernel through :func:`kernel_value`: the direct sum and the hierarchical near
field through :class:`~meshshade.surface.pair_kernel.PairKernel` (:func:`kernel_values`, a loop over arrays of
pairs), the hierarchical far field inside its traversal (surface/hierarchy_loops.py, per pair). The physics
lives in meshshade.kernels, each equation in one compiled scalar function:

==========================  ===================================================================================
kernel (models.Kernel)      evaluation
==========================  ===================================================================================
DIPOLE_SURFACE, _CHORD      :func:`~meshshade.kernels.dipole.dipole_diffuse_reflectance` (docs/physics.md eq. (15))
                            of the surface distance or of the chord
CURVED                      :func:`~meshshade.kernels.curvature.table.curved_dipole` (eqs. (49)-(53), soft policy)
EXACT_SPHERE                the exact sphere series of the source's local radius
                            (:func:`~meshshade.kernels.sphere.sphere_series_profile`), tabulated per radius bin by
                            :class:`SphereTables` and read log-linearly in theta (:func:`sphere_table_value`)
FITTED                      :func:`~meshshade.kernels.fitted_curvature.fitted_dipole` (eqs. (82)-(84))
==========================  ===================================================================================

A pair is given by its chord and surface distance (mm), the source's normal curvatures towards the receiver and
across it (1/mm), its squared twist (1/mm^2, the fitted model) and its sphere-table row. The per-channel constants
travel in one typed record, :class:`KernelParams`, built once per material and cutoff by :func:`kernel_params`.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from meshshade.kernels.curvature import CurvatureTable
from meshshade.kernels.curvature.policies import SOFT
from meshshade.kernels.curvature.table import curved_dipole, kernel_ratios
from meshshade.kernels.dipole import dipole_diffuse_reflectance
from meshshade.kernels.fitted_curvature import (effective_coefficients, euler_curvatures, fitted_dipole,
                                                fitted_row_table, matched_table, shipped_coefficients)
from meshshade.kernels.sphere import sphere_series_profile
from meshshade.materials import Material
from meshshade.surface.models import Kernel

#: relative width of the exact-sphere radius bins and the number of points of their theta grid over [0, pi]
SPHERE_RADIUS_RTOL = 1e-3
SPHERE_THETA_POINTS = 4097

# the kernels as plain integers for the compiled code (models.Kernel is the one enumeration)
DIPOLE_SURFACE, CURVED, EXACT_SPHERE, FITTED, DIPOLE_CHORD = (int(Kernel.DIPOLE_SURFACE), int(Kernel.CURVED),
                                                              int(Kernel.EXACT_SPHERE), int(Kernel.FITTED),
                                                              int(Kernel.DIPOLE_CHORD))


class KernelParams(NamedTuple):
    """Per-channel constants of :func:`kernel_value` (rows: channels r, g, b; optical units unless said).

    sigma_t (3,) 1/mm; albedo, mu, z_r, z_b, z_v (3,): the diffusion parameters; rd0 (3,): the dipole's R_d(0);
    curv_a0 (3,): the curvature ratio a(0); curv_coef (3, n, 16), curv_n (3,) int64: each channel's
    :class:`~meshshade.kernels.curvature.CurvatureTable` coefficients (padded) and interval count; fit_theta (3, 16):
    the fitted model's effective coefficients; fit_coef (3, n, 32): its row tables
    (:func:`~meshshade.kernels.fitted_curvature.fitted_row_table`); fit_z_b (3,): the matched boundary's z_b;
    sphere_log (3 bins, m): log R [1/mm^2] of the exact sphere per radius bin and channel (rows ``3 bin + c``) on
    a uniform theta grid; sphere_r0 (bins,) mm: each bin's radius.
    """

    sigma_t: np.ndarray
    albedo: np.ndarray
    mu: np.ndarray
    z_r: np.ndarray
    z_b: np.ndarray
    z_v: np.ndarray
    rd0: np.ndarray
    curv_a0: np.ndarray
    curv_coef: np.ndarray
    curv_n: np.ndarray
    fit_theta: np.ndarray
    fit_coef: np.ndarray
    fit_z_b: np.ndarray
    sphere_log: np.ndarray
    sphere_r0: np.ndarray


def kernel_params(material: Material, rho_max_mm, sphere: "SphereTables | None" = None, *,
                  curvature: bool = True) -> KernelParams:
    """The :class:`KernelParams` of ``material`` with curvature tables reaching ``rho_max_mm`` (scalar or (3,) mm per
    channel; 1.25 times that, at least 10 transport lengths: the kernels compute beyond a table directly) and the
    exact-sphere tables of ``sphere`` (none when None). ``curvature=False``: no curvature or fitted tables (the
    dipole and exact-sphere kernels do not read them)."""
    p = material.medium.jensen
    st = np.ascontiguousarray(material.sigma_t_prime, dtype=np.float64)
    b3 = lambda v: np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=np.float64), (3,)))  # noqa: E731
    al, mu, zr, zv = b3(p.albedo_prime), b3(p.mu), b3(p.z_r), b3(p.z_v)
    rd0 = np.array([dipole_diffuse_reflectance(0.0, al[c], mu[c], zr[c], zv[c]) for c in range(3)])
    sph_log, sph_r0 = (np.zeros((3, 2)), np.ones(1)) if sphere is None or not sphere.r0.size else (sphere.log_table,
                                                                                                 sphere.r0)
    if not curvature:
        return KernelParams(st, al, mu, zr, b3(p.z_b), zv, rd0, np.zeros(3), np.zeros((3, 1, 16)),
                            np.zeros(3, np.int64), np.zeros((3, 16)), np.zeros((3, 1, 32)), np.zeros(3), sph_log,
                            sph_r0)
    reach = np.broadcast_to(np.asarray(rho_max_mm, dtype=np.float64), (3,))
    tables = [CurvatureTable(float(material.albedo_prime[c]), float(material.eta),
                             max(float(reach[c] * st[c]) * 1.25, 10.0)) for c in range(3)]
    n_int = np.array([t.coef.shape[0] for t in tables], dtype=np.int64)
    coef = np.zeros((3, int(n_int.max()), tables[0].coef.shape[1]))
    for c, t in enumerate(tables):
        coef[c, :t.coef.shape[0]] = t.coef
    a0 = np.array([t.a0 for t in tables])
    # the fitted model: per channel its effective coefficients and its table (fitted_row_table: the material's and
    # the matched boundary's ratios and the near-source functions on the same intervals), padded as coef
    fit = np.stack([effective_coefficients(shipped_coefficients(), float(np.ravel(p.A)[0]) - 1.0)] * 3)
    matched = [matched_table(t) for t in tables]
    rows = [fitted_row_table(t, m, fit[c]) for c, (t, m) in enumerate(zip(tables, matched))]
    fit_coef = np.zeros((3, coef.shape[1], rows[0].shape[1]))
    for c, r in enumerate(rows):
        fit_coef[c, :r.shape[0]] = r
    fit_zb = np.array([t.z_b for t in matched])
    return KernelParams(st, al, mu, zr, b3(p.z_b), zv, rd0, a0, coef, n_int, fit, fit_coef, fit_zb, sph_log, sph_r0)


class SphereTables:
    """The exact sphere's kernel tabulated per local radius: radii ``2/(k1 + k2)`` of convex sources binned to a
    relative width :data:`SPHERE_RADIUS_RTOL`, per bin and channel log R [1/mm^2] on :data:`SPHERE_THETA_POINTS`
    angles over [0, pi] (:func:`~meshshade.kernels.sphere.sphere_series_profile` at ``rtol``). Bins are added as
    sources ask for them (:meth:`rows`); ``log_table`` (3 bins, m) and ``r0`` (bins,) mm are what
    :class:`KernelParams` carries."""

    def __init__(self, material: Material, rtol: float = 1e-10):
        self.material, self.rtol = material, float(rtol)
        self.theta = np.linspace(0.0, np.pi, SPHERE_THETA_POINTS)
        self._bins: dict = {}                 # bin key -> row
        self.r0 = np.zeros(0)
        self.log_table = np.zeros((0, SPHERE_THETA_POINTS))

    @staticmethod
    def bin_keys(H) -> np.ndarray:
        """(k,) int64: the radius bin of each mean curvature ``H`` (1/mm); -1 where the source is not convex."""
        H = np.asarray(H, dtype=np.float64)
        convex = H > 0
        radius = np.where(convex, 1.0 / np.where(convex, H, 1.0), 1.0)
        return np.where(convex, np.round(np.log(radius) / np.log1p(SPHERE_RADIUS_RTOL)), -1).astype(np.int64)

    @staticmethod
    def bin_radius(key) -> float:
        """The radius (mm) of bin ``key``."""
        return float(np.exp(key * np.log1p(SPHERE_RADIUS_RTOL)))

    def rows(self, H) -> np.ndarray:
        """(k,) int64: each source's table row (``3 row + c`` in ``log_table``) from its mean curvature ``H``;
        -1 where it is not convex. Tables of new bins are computed now (3 series over the theta grid each)."""
        return self.rows_of_keys(self.bin_keys(H))

    def rows_of_keys(self, keys) -> np.ndarray:
        """:meth:`rows` of radius bins ``keys`` (:meth:`bin_keys`)."""
        keys = np.asarray(keys, dtype=np.int64)
        new = [int(b) for b in np.unique(keys[keys >= 0]) if int(b) not in self._bins]
        if new:
            tab = np.empty((3 * len(new), SPHERE_THETA_POINTS))
            for i, b in enumerate(new):
                R0 = self.bin_radius(b)
                for c in range(3):
                    tab[3 * i + c] = np.log(np.maximum(self.series(c, R0, self.theta), 1e-300))
                self._bins[b] = self.r0.size + i
            self.r0 = np.concatenate([self.r0, [self.bin_radius(b) for b in new]])
            self.log_table = np.vstack([self.log_table, tab])
        out = np.full(keys.shape, -1, dtype=np.int64)
        on = keys >= 0
        out[on] = [self._bins[int(b)] for b in keys[on]] if np.any(on) else []
        return out

    def series(self, c: int, R0_mm: float, theta) -> np.ndarray:
        """R [1/mm^2] of channel ``c`` on the sphere of radius ``R0_mm`` at angles ``theta``, by the series."""
        ch = self.material.channel(c)
        st = ch["sigma_t_prime"]
        return sphere_series_profile(theta, R0_opt=R0_mm * st, albedo_prime=ch["albedo_prime"], eta=ch["eta"],
                                     rtol=self.rtol) * st * st


@numba.njit(cache=True, error_model="numpy", inline="always")
def sphere_table_value(log_table, r0, row, c, s):
    """R [1/mm^2] of channel ``c`` at surface distance ``s`` (mm) from table row ``row`` of :class:`SphereTables`:
    log-linear interpolation on the uniform theta grid (relative error ~1e-5, up to 1e-4 within a few grid steps of
    the peak on spheres of tens of transport lengths: tests/surface/test_kernel_evaluation.py)."""
    r = row * 3 + c
    th = min(s / r0[row], math.pi)
    m = log_table.shape[1] - 1
    f = th / math.pi * m
    i = min(int(f), m - 1)
    w = f - i
    return math.exp((1.0 - w) * log_table[r, i] + w * log_table[r, i + 1])


@numba.njit(cache=True, error_model="numpy", inline="always")
def kernel_value(kind, c, chord, s, kn, knp, t2, sph_row, p):
    """R [1/mm^2] of channel ``c`` for one pair: ``kind`` a :class:`~meshshade.surface.models.Kernel`, chord and
    surface distance ``s`` (mm), the source's normal curvatures towards the receiver and across ``kn``, ``knp``
    (1/mm), its squared twist ``t2`` (1/mm^2, FITTED), its sphere-table row (EXACT_SPHERE; -1: the chord dipole),
    ``p`` the :class:`KernelParams`."""
    sc = p.sigma_t[c]
    if kind == DIPOLE_CHORD:
        return dipole_diffuse_reflectance(chord * sc, p.albedo[c], p.mu[c], p.z_r[c], p.z_v[c]) * sc * sc
    if kind == DIPOLE_SURFACE:
        return dipole_diffuse_reflectance(s * sc, p.albedo[c], p.mu[c], p.z_r[c], p.z_v[c]) * sc * sc
    if kind == FITTED:
        return fitted_dipole(s * sc, kn / sc, knp / sc, t2 / (sc * sc), p.fit_coef[c], p.curv_n[c], p.albedo[c],
                             p.mu[c], p.z_r[c], p.z_b[c], p.fit_z_b[c], p.z_v[c], p.fit_theta[c]) * sc * sc
    if kind == CURVED:
        return curved_dipole(s * sc, kn / sc, knp / sc, p.curv_coef[c], p.curv_n[c], p.albedo[c], p.mu[c], p.z_r[c],
                             p.z_b[c], p.z_v[c], p.curv_a0[c], p.rd0[c], SOFT) * sc * sc
    if sph_row < 0:   # the exact sphere where the source is not convex: the chord dipole
        return dipole_diffuse_reflectance(chord * sc, p.albedo[c], p.mu[c], p.z_r[c], p.z_v[c]) * sc * sc
    return sphere_table_value(p.sphere_log, p.sphere_r0, sph_row, c, s)


def per_kernel(loop, **options) -> dict:
    """``{kind: loop compiled with that kind fixed}`` for every :class:`~meshshade.surface.models.Kernel`:
    ``loop(kind)`` returns a plain function that reads ``kind`` as a constant (a closure); each is compiled with
    ``numba.njit(cache=True, **options)`` on its first call only.

    Why: with ``kind`` a constant numba drops the other kernels' branches of :func:`kernel_value` before typing, so
    a compiled loop holds one kernel's code: it runs as fast as a loop written for that kernel (with the kind read
    per pair the dipole loop ran at about 300 ns per pair, 7x slower), and compiling it costs that kernel alone, not
    all five (a dipole bake compiled the curved, fitted and exact-sphere kernels too: a third of ``meshshade
    demo``'s first run). numba's cache keeps each by its closure's value."""
    return {int(k): numba.njit(cache=True, **options)(loop(int(k))) for k in Kernel}


def _values_loop(kind):
    def kernel_values_of_kind(c, chord, s, kn, knp, t2, sph_row, p, out):
        for j in range(s.size):
            out[j] = kernel_value(kind, c, chord[j], s[j], kn[j], knp[j], t2[j], sph_row[j], p)
    return kernel_values_of_kind


_VALUES = per_kernel(_values_loop, error_model="numpy")


def kernel_values(kind, c, chord, s, kn, knp, t2, sph_row, p, out):
    """:func:`kernel_value` of one ``kind`` over arrays of pairs (all (k,); ``sph_row`` int64) into ``out``: the
    compiled loop of that kind (:func:`per_kernel`), compiled on its first call."""
    _VALUES[int(kind)](c, chord, s, kn, knp, t2, sph_row, p, out)


@numba.njit(cache=True, error_model="numpy")
def curved_values(c, s, phi, k1, k2, p, tol, out):
    """The CURVED kernel over arrays of pairs whose sources' principal curvatures ``k1``, ``k2`` (1/mm) and the
    pairs' azimuths ``phi`` from the first principal direction are given (the normal curvatures by Euler's formula,
    :func:`~meshshade.kernels.fitted_curvature.euler_curvatures`), into ``out``; one pass, no temporaries. Returns
    the number of pairs outside the first-order range, ``max(|k1|, |k2|) (|a| + |b| + z_r) > tol`` (optical
    units; :func:`~meshshade.kernels.curvature.coefficients.curvature_validity`)."""
    sc = p.sigma_t[c]
    n_out = 0
    for j in range(s.size):
        ka, kc, _ = euler_curvatures(phi[j], k1[j], k2[j])
        out[j] = kernel_value(CURVED, c, s[j], s[j], ka, kc, 0.0, -1, p)
        kmax = max(abs(k1[j]), abs(k2[j])) / sc
        if kmax > 0.0:
            ra, rb = kernel_ratios(s[j] * sc, p.curv_coef[c], p.curv_n[c], p.mu[c], p.z_r[c], p.z_b[c])
            if not kmax * (abs(ra) + abs(rb) + p.z_r[c]) <= tol:
                n_out += 1
    return n_out
