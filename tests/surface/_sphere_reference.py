"""Exact exitance of a sphere under a directional light: the reference of test_sphere_directional_reference.py.

Derivation
----------
A sphere of radius R (mm) lit by a directional light of irradiance E0 (W/mm^2 across the beam) along -z. Every
point y of the upper hemisphere is lit (a sphere is convex: nothing shadows it), and the power per unit area that
crosses the boundary there is (docs/physics.md eq. (56), with A_v -> dA)

    q(y) = E0 w(c(y)),     w(c) = max(c, 0) F_t(c, eta),     c(y) = z_hat . n(y) = cos(theta_i),

F_t the unpolarised Fresnel transmittance (physics.md §3, eq. (11), (13); written out again below, independently
of meshshade.kernels.fresnel). Diffusion theory with the exact sphere kernel R_sph (physics.md §5.2, eq. (23))
makes the exitance at an exit point x

    M(x) = int_S q(y) R_sph(gamma(x, y)) dA(y),

gamma the great-circle angle between x and y. By symmetry M depends only on the polar angle beta of x from the
sub-light point (the north pole). Put polar coordinates (gamma, psi) on the sphere *centred on x* (gamma the angle
from x, psi the azimuth about x measured from the great circle through the pole): dA = R^2 sin(gamma) dgamma dpsi
and, by the spherical law of cosines,

    c(gamma, psi) = cos(beta) cos(gamma) + sin(beta) sin(gamma) cos(psi).

The kernel depends on gamma alone and the integrand is even in psi, so

    M(beta) = 2 E0 R^2 int_0^pi R_sph(gamma) sin(gamma) I(beta, gamma) dgamma,
    I(beta, gamma) = int_0^psi_max w(c(gamma, psi)) dpsi,
    psi_max = arccos(clip(-cot(beta) cot(gamma), -1, 1))       (c > 0 exactly for psi < psi_max).

The inner integral runs over the lit arc only, so its integrand is smooth (analytic in psi up to the end point,
where w vanishes linearly in c); Gauss-Legendre on [0, psi_max] converges fast. In gamma, I changes form where the
circle of radius gamma about x starts to leave the lit cap (gamma = |pi/2 - beta|) and where it leaves it entirely
(gamma = pi/2 + beta): both are panel breaks. The kernel peaks at gamma = 0 with a width of a few transport
lengths: the gamma panels are graded in arc length s = R gamma (0, 1/8, 1/4, 1/2, 1, 2 mm, then steps of
``STEP_MM`` up to ``UNIFORM_MM``, growing by ``GROWTH`` beyond), with ``n_gamma`` Gauss-Legendre nodes each.

The only code of meshshade used is the kernel itself, ``meshshade.kernels.sphere.sphere_series_profile``, which
is tested on its own against mpmath evaluations of the Bessel series (tests/kernels). The transport integral, the
Fresnel factor and the geometry are written here.

Checks (tests in test_sphere_directional_reference.py): convergence under doubling of both node counts; the total
exitant power int M dA = 2 pi R^2 int_0^pi M(beta) sin(beta) dbeta equals the entering power
E0 2 pi R^2 int_0^1 c F_t(c) dc times the closed-form sphere albedo alpha' T (physics.md eq. (33)); and the planar
limit: on a huge sphere M(0) -> E0 F_t(1) alpha' T.
"""
from __future__ import annotations

import numpy as np

from meshshade.kernels.sphere import sphere_series_profile

#: gamma panels of STEP_MM beyond the graded start up to UNIFORM_MM of arc, growing by GROWTH beyond (a huge sphere:
#: there the kernel is below 1e-9 of its peak for the materials tested)
STEP_MM, UNIFORM_MM, GROWTH = 2.0, 200.0, 1.5


def fresnel_transmittance(c, eta: float) -> np.ndarray:
    """Unpolarised Fresnel transmittance 1 - F from air into a medium of index ``eta`` >= 1 at incidence cosine
    ``c`` in [0, 1] (Born & Wolf §1.5.2; physics.md eq. (11))."""
    c = np.clip(np.asarray(c, dtype=np.float64), 0.0, 1.0)
    ct = np.sqrt(eta * eta - 1.0 + c * c) / eta
    rs = (c - eta * ct) / (c + eta * ct)
    rp = (eta * c - ct) / (eta * c + ct)
    return 1.0 - 0.5 * (rs * rs + rp * rp)


def _channel(material, channel: int):
    st = float(material.sigma_t_prime[channel])
    return st, {"albedo_prime": float(material.albedo_prime[channel]), "eta": float(material.eta)}


def _panels(breaks: np.ndarray, n: int):
    """Gauss-Legendre nodes and weights of the panels between consecutive ``breaks`` (..., p + 1), vectorised over
    leading axes: returns (..., p * n) nodes and weights (zero-width panels get zero weight)."""
    x, w = np.polynomial.legendre.leggauss(n)
    lo, hi = breaks[..., :-1, None], breaks[..., 1:, None]
    half = 0.5 * (hi - lo)
    nodes = lo + half * (x + 1.0)
    weights = half * w
    shape = breaks.shape[:-1] + (-1,)
    return nodes.reshape(shape), weights.reshape(shape)


def sphere_directional_exitance(beta, *, R_mm: float, material, channel: int = 0, irradiance: float = 1.0,
                                n_gamma: int = 16, n_psi: int = 24, block: int = 64) -> np.ndarray:
    """Exact exitance M [W/mm^2] at polar angles ``beta`` (rad, any shape) from the sub-light point of a sphere of
    radius ``R_mm`` under a directional light of ``irradiance`` W/mm^2 (module docstring for the derivation).

    ``n_gamma``, ``n_psi``: Gauss-Legendre nodes per gamma panel and over the lit psi arc (the defaults are
    converged to < 1e-7 relative wherever M > 1e-3 of its peak, R = 20 mm, sigma_s' = 1, sigma_a = 0.01 /mm).
    """
    st, par = _channel(material, channel)
    beta = np.asarray(beta, dtype=np.float64)
    flat = beta.reshape(-1)
    half_turn = np.pi * R_mm
    graded = [0.0, 0.125, 0.25, 0.5, 1.0]
    uniform = np.arange(2.0, UNIFORM_MM + 1e-9, STEP_MM)
    grown = UNIFORM_MM * GROWTH ** np.arange(
        1, int(np.ceil(np.log(max(half_turn / UNIFORM_MM, 1.0)) / np.log(GROWTH))) + 1)
    s_breaks = np.unique(np.concatenate([graded, uniform, grown, [half_turn]]))
    s_breaks = s_breaks[s_breaks <= half_turn] / R_mm
    xp, wp = np.polynomial.legendre.leggauss(n_psi)
    out = np.empty(flat.shape)
    for a in range(0, flat.size, block):   # blocks of exit angles: bounded memory
        b = flat[a:a + block]
        extra = np.stack([np.abs(0.5 * np.pi - b), np.minimum(0.5 * np.pi + b, np.pi)], axis=1)
        breaks = np.sort(np.concatenate([np.broadcast_to(s_breaks, (b.size, s_breaks.size)), extra], axis=1),
                         axis=1)
        gam, wg = _panels(breaks, n_gamma)                            # (nb, ng)
        kern = sphere_series_profile(gam.reshape(-1), R0_opt=R_mm * st, rtol=1e-13, **par).reshape(gam.shape)
        kern = kern * st * st                                          # mm^-2
        A = np.cos(b)[:, None] * np.cos(gam)
        B = np.sin(b)[:, None] * np.sin(gam)                           # >= 0
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(B > 0, -A / B, np.where(A > 0, -np.inf, np.inf))
        psi_max = np.arccos(np.clip(ratio, -1.0, 1.0))                 # lit arc [0, psi_max]
        psi = 0.5 * psi_max[..., None] * (xp + 1.0)                    # (nb, ng, npsi)
        c = A[..., None] + B[..., None] * np.cos(psi)
        w = np.maximum(c, 0.0) * fresnel_transmittance(c, par["eta"])
        inner = 0.5 * psi_max * (w @ wp)                               # I(beta, gamma)
        out[a:a + block] = 2.0 * R_mm * R_mm * np.sum(wg * kern * np.sin(gam) * inner, axis=1)
    return irradiance * out.reshape(beta.shape)


def entering_power(*, R_mm: float, eta: float, irradiance: float = 1.0, n: int = 64) -> float:
    """Power [W] crossing into the sphere: E0 2 pi R^2 int_0^1 c F_t(c) dc (Gauss-Legendre, ``n`` nodes)."""
    x, w = np.polynomial.legendre.leggauss(n)
    c = 0.5 * (x + 1.0)
    return irradiance * 2.0 * np.pi * R_mm ** 2 * float(np.sum(0.5 * w * c * fresnel_transmittance(c, eta)))


def exitant_power(*, R_mm: float, material, channel: int = 0, irradiance: float = 1.0, n_beta: int = 24,
                  **kw) -> float:
    """Total exitant power [W] of :func:`sphere_directional_exitance`: 2 pi R^2 int_0^pi M(beta) sin(beta) dbeta,
    Gauss-Legendre panels in beta, graded towards the terminator, where M changes fastest."""
    t = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 0.45, 0.48, 0.5, 0.52, 0.55, 0.6, 0.7, 0.8, 0.9, 1.0]) * np.pi
    beta, wb = _panels(t, n_beta)
    M = sphere_directional_exitance(beta, R_mm=R_mm, material=material, channel=channel, irradiance=irradiance,
                                    **kw)
    return 2.0 * np.pi * R_mm ** 2 * float(np.sum(wb * M * np.sin(beta)))
