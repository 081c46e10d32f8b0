"""The diffusion equation's half-space with the Robin boundary (docs/physics.md §15, eqs. (93) and (96)).

What the volume transport solves (eq. (89)) has, on a half-space, an exact solution for an isotropic unit point
source at depth t: eq. (93) as a Hankel integral. For the bake it is written as free-space Green's functions
G(d) = exp(-mu d) / (4 pi D d): the source, its mirror image at height t, and a line of negative images running
up from the mirror image with density (2/l) exp(-s/l) (l = 2 A D, the Robin length), eq. (96):

    phi(rho, 0) = 2 G(d_0) - (2/l) int_0^inf exp(-s/l) G(d_s) ds,     d_s = sqrt(rho^2 + (t + s)^2),

and the exitance is M = phi / (2 A) (eq. (92)). The single integral is smooth once s = d_0 (e^v - 1): a fixed
Gauss-Legendre rule in v. Its limits: l -> 0 is the Dirichlet condition on the surface (phi = 0), l -> inf the
Neumann one (twice the free-space fluence). Every radial integral of eq. (96) over a disc is elementary in rho
(d dd = rho drho), so the disc power and the total reduce to a smooth integral over s as well; the total is
eq. (93)'s closed form exp(-mu t) / (1 + 2 A D mu).

Pure array functions in any consistent length unit (mm and 1/mm, or optical units): ``D`` the diffusion
coefficient, ``mu`` = sqrt(sigma_a / D) the effective attenuation, ``A`` the boundary's reflection parameter.
"""
from __future__ import annotations

import math

import numpy as np

from meshshade.errors import MaterialError

__all__ = ["robin_point_source_exitance", "robin_point_source_disc", "robin_point_source_total",
           "robin_smoothed_exitance", "robin_smoothed_exitances"]

# the smooth integral over the image line: Gauss-Legendre in v = ln(1 + s / d_0) up to s = LINE_REACH l (the
# exp(-s / l) weight is below 1e-19 there)
_V_NODES, _V_WEIGHTS = np.polynomial.legendre.leggauss(96)
LINE_REACH = 44.0


def _check(D, mu, A):
    if not (D > 0 and mu >= 0 and A > 0 and math.isfinite(D * mu * A)):
        raise MaterialError(f"the Robin half-space needs D > 0, mu >= 0 and A > 0, got D={D!r}, mu={mu!r}, A={A!r}")


def robin_point_source_exitance(rho, depth, *, D, mu, A):
    """M(rho) of eq. (96) (= eq. (93)) for a unit isotropic source at ``depth`` > 0 (arrays broadcast; rho >= 0).

    Per unit source power, per unit area. Finite everywhere for depth > 0 (peak ~ depth^-2 at rho = 0)."""
    D, mu, A = float(D), float(mu), float(A)
    _check(D, mu, A)
    rho, t = np.broadcast_arrays(np.asarray(rho, dtype=np.float64), np.asarray(depth, dtype=np.float64))
    if np.any(t <= 0) or np.any(rho < 0):
        raise MaterialError("the Robin half-space source must lie below the surface (depth > 0), rho >= 0")
    ell = 2.0 * A * D
    d0 = np.sqrt(rho * rho + t * t)[..., None]
    tt, rr = t[..., None], rho[..., None]
    v_max = np.log1p(LINE_REACH * ell / d0)
    v = 0.5 * v_max * (_V_NODES + 1.0)
    s = d0 * np.expm1(v)
    ds = np.sqrt(rr * rr + (tt + s) ** 2)
    # integrand of (2/l) int exp(-s/l) G(d_s) ds in v (ds/dv = s + d0), with G's exp(-mu d0) factored out
    f = np.exp(-s / ell - mu * (ds - d0)) * (s + d0) / ds
    line = (2.0 / ell) * 0.5 * v_max[..., 0] * np.sum(_V_WEIGHTS * f, axis=-1)
    d0 = d0[..., 0]
    phi = np.exp(-mu * d0) / (4.0 * math.pi * D) * (2.0 / d0 - line)
    return (phi / (2.0 * A))[()]


def _disc_fluence(a, t, D, mu):
    """int_0^a 2 pi rho G(sqrt(rho^2 + t^2)) drho = exp(-mu t) (1 - exp(-mu (d_a - t))) / (2 D mu) (mu -> 0 safe)."""
    da = np.sqrt(a * a + t * t)
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(mu * (da - t) > 1e-12, -np.expm1(-mu * (da - t)) / np.where(mu > 0, mu, 1.0), da - t)
    return np.exp(-mu * t) * frac / (2.0 * D)


def robin_point_source_disc(a, depth, *, D, mu, A):
    """int_0^a M(rho) 2 pi rho drho: the power leaving through the disc of radius ``a`` (arrays broadcast; a may be
    inf, giving :func:`robin_point_source_total`)."""
    D, mu, A = float(D), float(mu), float(A)
    _check(D, mu, A)
    a, t = np.broadcast_arrays(np.asarray(a, dtype=np.float64), np.asarray(depth, dtype=np.float64))
    ell = 2.0 * A * D
    inf = np.isinf(a)
    af = np.where(inf, 0.0, a)
    d0 = np.maximum(np.sqrt(af * af + t * t), 1e-300)[..., None]
    v_max = np.log1p(LINE_REACH * ell / d0)
    v = 0.5 * v_max * (_V_NODES + 1.0)
    s = d0 * np.expm1(v)                                # the image line, s = d0 (e^v - 1) as in the exitance
    f = np.exp(-s / ell) * _disc_fluence(af[..., None], t[..., None] + s, D, mu) * (s + d0)
    line = (2.0 / ell) * 0.5 * v_max[..., 0] * np.sum(_V_WEIGHTS * f, axis=-1)
    out = (2.0 * _disc_fluence(af, t, D, mu) - line) / (2.0 * A)
    total = robin_point_source_total(t, D=D, mu=mu, A=A)
    return np.where(inf, total, out)[()]


def robin_point_source_total(depth, *, D, mu, A):
    """Eq. (93)'s total: exp(-mu t) / (1 + 2 A D mu), the power that leaves the half-space per unit source power."""
    D, mu, A = float(D), float(mu), float(A)
    _check(D, mu, A)
    t = np.asarray(depth, dtype=np.float64)
    return (np.exp(-mu * t) / (1.0 + 2.0 * A * D * mu))[()]


#: the smoothed exitance's Hankel integral runs to k = HANKEL_REACH / s (the Gaussian factor is exp(-32) there)
HANKEL_REACH = 8.0
_K_NODES, _K_WEIGHTS = np.polynomial.legendre.leggauss(16)


def robin_smoothed_exitance(rho, depths, strengths, *, D, mu, A, spread, scaled=True):
    """Eq. (101) for one set of sources: see :func:`robin_smoothed_exitances` (which takes several sets at once)."""
    M, disc, total = robin_smoothed_exitances(rho, [depths], [strengths], D=D, mu=mu, A=A, spread=spread,
                                              scaled=scaled)
    return M[0], disc[0], float(total[0])


def robin_smoothed_exitances(rho, depths, strengths, *, D, mu, A, spread, scaled=True):
    """The exitance of point sources at ``depths`` (s, n) with ``strengths`` (s, n) (s sets of n sources), each
    spread sideways by a Gaussian of standard deviation ``spread`` in the plane of the surface (docs/physics.md
    eq. (101)): (M (s, len rho) per unit area, its disc integral int_0^rho M 2 pi r dr (s, len rho), its total
    (s,)); the Bessel functions are evaluated once for all sets. ``scaled``: times
    exp(-mu^2 spread^2 / 2), the Ewald weight of eq. (100) that keeps the point's far field.

    From eq. (93)'s Hankel transform, the Gaussian multiplies it by exp(-k^2 s^2 / 2):

        M(rho) = 1/(2 pi) int_0^inf k J0(k rho) H(k) dk,   disc(a) = a int_0^inf J1(k a) H(k) dk,
        H(k) = sum_j q_j exp(-m t_j) e(m) / (1 + 2 A D m),   m = sqrt(k^2 + mu^2),

    e(m) = exp(-m^2 s^2 / 2) scaled (exp(-k^2 s^2 / 2) otherwise); the integrals end where the Gaussian has died
    (k = 8 / s) and are taken by Gauss-Legendre with enough nodes for the oscillations of J0 up to max(rho). J0
    and J1 are bounded: no overflow. Any consistent length unit; ``spread`` > 0."""
    from scipy.special import j0, j1

    D, mu, A, s = float(D), float(mu), float(A), float(spread)
    _check(D, mu, A)
    if not s > 0:
        raise MaterialError(f"the sideways spread must be positive, got {spread!r}")
    rho = np.asarray(rho, dtype=np.float64).ravel()
    t = np.atleast_2d(np.asarray(depths, dtype=np.float64))
    q = np.atleast_2d(np.asarray(strengths, dtype=np.float64))
    K = HANKEL_REACH / s
    # composite Gauss-Legendre (16 nodes a panel) with about 4 nodes per half period of J0 at the largest rho
    panels = int(min(2000, max(16, math.ceil(4.0 * K * float(rho.max(initial=0.0)) / math.pi / 16.0))))
    edges = np.linspace(0.0, K, panels + 1)
    half = 0.5 * np.diff(edges)
    k = ((edges[:-1] + half)[:, None] + half[:, None] * _K_NODES[None, :]).ravel()
    kw = (half[:, None] * _K_WEIGHTS[None, :]).ravel()
    m = np.sqrt(k * k + mu * mu)
    e = np.exp(-0.5 * (m * s) ** 2) if scaled else np.exp(-0.5 * (k * s) ** 2)
    H = np.einsum("sn,ksn->sk", q, np.exp(-m[:, None, None] * t[None, :, :])) * (e / (1.0 + 2.0 * A * D * m))
    M = np.empty((t.shape[0], rho.size))
    disc = np.empty((t.shape[0], rho.size))
    for i in range(0, rho.size, 128):
        kr = np.outer(rho[i:i + 128], k)
        M[:, i:i + 128] = (H * (kw * k)) @ j0(kr).T / (2.0 * math.pi)
        disc[:, i:i + 128] = rho[i:i + 128] * ((H * kw) @ j1(kr).T)
    total = (np.sum(q * np.exp(-mu * t), axis=1) * (math.exp(-0.5 * (mu * s) ** 2) if scaled else 1.0)
             / (1.0 + 2.0 * A * D * mu))
    return M, disc, total
