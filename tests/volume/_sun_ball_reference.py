"""The sun-lit ball's exact solution (docs/physics.md §15), independent of the bake's discretisation and tables:
loaded by path by tests/volume/test_volume_sun_ball.py and tests/output/test_texture.py (nothing here imports the
volume transport).

A ball of radius R = 20 mm (sigma_s' = 1, sigma_a = 0.01 /mm, eta 1.3) under a unit sun along -z:

* :func:`sun_ball_exitance`: the exact Robin ball series (eq. (94), tests/volume/_volume_reference.py's
  0F1 ratios, no Bessel function formed) of the line sources of eq. (97) of a *continuous* sun (every entry point
  of the lit hemisphere with power E cos (1 - F) per unit area, along the refracted direction written here),
  summed over the azimuth by the addition theorem (only m = 0 survives); the line by an 8-point Gauss-Laguerre
  rule (numpy's laggauss; the bake uses 6), 600 Gauss-Legendre polar angles, 2500 terms;
* :func:`near_field_ball`: the continuum limit of the near field less the half-space diffusion of the same line
  sources, eq. (98), evaluated from its definition: the public kernels R_near (eq. (76)), W (eq. (86)) and
  M_Robin (eq. (96)) (numpy's laggauss, not the bake's tables); integrated over the lit surface of the exact
  sphere facing the receiver's way by Gauss-Legendre in log angle x midpoint rule in azimuth, within the radius
  where the magnitude of Delta R beyond holds 1 % of R_near's total, with that remainder's signed energy at the
  entry point (docs/physics.md §15.1);
* d'Eon's D and A of eq. (74) computed here (Fresnel moments C1, C2 by adaptive quadrature of Born & Wolf's
  Fresnel reflectance).
"""
from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
from scipy import integrate

from meshshade.kernels.near_field import incidence_gain, near_field_profile
from meshshade.kernels.robin_halfspace import robin_point_source_exitance
from meshshade.materials import Material

_spec = importlib.util.spec_from_file_location("volume_reference", Path(__file__).with_name("_volume_reference.py"))
_ref = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_ref)
bessel_ratio = _ref.bessel_ratio

R = 20.0
MATERIAL = Material([1.0, 1.0, 1.0], [0.01, 0.01, 0.01], eta=1.3)
#: docs/physics.md §15.1: Delta R is summed within the radius where what lies beyond holds 1 % of R_near's total
NEAR_TAIL = 1e-2
#: Gauss-Laguerre points of the reference's line sources
LINE_POINTS = 8


def refracted(d, n, eta):
    """(k, 3) unit refracted directions of the incident unit ``d`` (3,) through the surface of outward normals
    ``n`` (k, 3) into a medium of relative index ``eta`` (Snell's law, vector form)."""
    ci = -(n @ d)
    ct = np.sqrt(1.0 - (1.0 - ci * ci) / eta ** 2)
    return d[None, :] / eta + (ci / eta - ct)[:, None] * n


def exact_at():
    """points (p, 3) on the ball -> the reference exitance (channel 0) at their polar angles, from
    :func:`ball_reference_exitance` on a 1/2 degree grid (linear between)."""
    theta = np.linspace(0.0, math.pi, 361)
    values = ball_reference_exitance(theta)

    def at(points):
        th = np.arccos(np.clip(points[:, 2] / np.linalg.norm(points, axis=1), -1.0, 1.0))
        return np.interp(th, theta, values)
    return at


def ball_reference_exitance(theta):
    """The whole reference at polar angles ``theta`` (channel 0; every channel is the same medium)."""
    D, _, A = deon_constants(float(MATERIAL.albedo_prime[0]), float(MATERIAL.eta))
    s = float(MATERIAL.sigma_t_prime[0])
    return sun_ball_exitance(theta, D / s, float(MATERIAL.sigma_a[0]), A) + near_field_ball(theta, MATERIAL, R)


def fresnel(cos_i, n1, n2):
    """Unpolarised Fresnel reflectance from index n1 into n2 (Born & Wolf 1.5.2); 1 past the critical angle."""
    cos_i = np.asarray(cos_i, dtype=np.float64)
    sin2_t = (n1 / n2) ** 2 * (1.0 - cos_i * cos_i)
    cos_t = np.sqrt(np.clip(1.0 - sin2_t, 0.0, None))
    rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
    rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i)
    return np.where(sin2_t >= 1.0, 1.0, 0.5 * (rs * rs + rp * rp))


def deon_constants(albedo, eta):
    """(D, mu, A) in optical units, d'Eon's theory (docs/physics.md eq. (74)): D = (2 - alpha')/3, mu =
    sqrt((1 - alpha')/D), A = (1 + 3 C2)/(1 - 2 C1), C_n = int_0^1 F(mu) mu^n dmu seen from inside."""
    mu_c = math.sqrt(1.0 - 1.0 / eta ** 2)                       # F = 1 below the critical cosine
    c1, c2 = (mu_c ** (n + 1) / (n + 1) + integrate.quad(lambda m: float(fresnel(m, eta, 1.0)) * m ** n, mu_c, 1.0,
                                                          epsabs=1e-14, epsrel=1e-12)[0] for n in (1, 2))
    D = (2.0 - albedo) / 3.0
    return D, math.sqrt((1.0 - albedo) / D), (1.0 + 3.0 * c2) / (1.0 - 2.0 * c1)


def delta_r(r_opt, cos_t, material):
    """Eq. (98) of channel 0, optical units, on the grid r_opt (n,) x cos_t (m,): W(cos_t) R_near(r) - sum_j
    alpha' w_j M_Robin(r; x_j cos_t), (x_j, w_j) the 4-point Gauss-Laguerre rule of eq. (97)."""
    a, eta, g = float(material.albedo_prime[0]), float(material.eta), float(material.g)
    D, mu, A = deon_constants(a, eta)
    x, w = np.polynomial.laguerre.laggauss(4)
    gain = np.array([incidence_gain(albedo_prime=a, eta=eta, g=g, cos_t=float(c)) for c in cos_t])
    near = near_field_profile(r_opt, albedo_prime=a, eta=eta, g=g)
    robin = sum(a * wj * robin_point_source_exitance(r_opt[:, None], xj * cos_t[None, :], D=D, mu=mu, A=A)
                for xj, wj in zip(x, w))
    return gain[None, :] * near[:, None] - robin


def near_field_radius_and_rest(material, n_r=1201, n_c=17):
    """(radius mm, cos_t grid, rest(cos_t)): the radius where the magnitude of Delta R beyond (its largest over
    cos_t) holds NEAR_TAIL of R_near's total, and the signed energy of Delta R beyond it per cos_t (trapezoid in
    ln r on [1e-6, 300] transport lengths, linear in ln r between the nodes; R_near's total by the same rule)."""
    a, eta, g = float(material.albedo_prime[0]), float(material.eta), float(material.g)
    lr = np.linspace(math.log(1e-6), math.log(300.0), n_r)
    r = np.exp(lr)
    cos_t = np.linspace(math.sqrt(1.0 - 1.0 / eta ** 2), 1.0, n_c)
    f = 2.0 * math.pi * r[:, None] ** 2 * delta_r(r, cos_t, material)        # d/d(ln r) of the ring integral

    def beyond(y):                                                  # int_{r_i}^inf y dln r at every node
        seg = 0.5 * (y[1:] + y[:-1]) * np.diff(lr).reshape((-1,) + (1,) * (y.ndim - 1))
        return np.concatenate([np.cumsum(seg[::-1], axis=0)[::-1], np.zeros((1,) + y.shape[1:])])

    near = 2.0 * math.pi * r ** 2 * near_field_profile(r, albedo_prime=a, eta=eta, g=g)
    tail = beyond(np.abs(f).max(axis=1))                            # non-increasing in r
    log_radius = float(np.interp(NEAR_TAIL * beyond(near)[0], tail[::-1], lr[::-1]))
    rest = np.array([np.interp(log_radius, lr, col) for col in beyond(f).T])
    return math.exp(log_radius) / float(material.sigma_t_prime[0]), cos_t, rest


def near_field_ball(theta_p, material, R, n_alpha=240, n_phi=80, n_c=64):
    """Continuum limit of the near-field correction (channel 0) on the exact ball of radius R under a unit sun
    from +z, at polar angles ``theta_p`` (module docstring): per receiver p, the lit points q within the radius
    (normals facing the same way there), each entering cos_i (1 - F) per unit area with its light at cos_t; plus
    the receiver's own entry times the rest beyond the radius."""
    s, eta = float(material.sigma_t_prime[0]), float(material.eta)
    radius, rest_c, rest = near_field_radius_and_rest(material)
    a_max = min(2.0 * math.asin(min(1.0, radius / (2.0 * R))), math.pi / 2)
    x, wx = np.polynomial.legendre.leggauss(n_alpha)
    la0, la1 = math.log(1e-9), math.log(a_max)
    al = np.exp(0.5 * (la1 - la0) * (x + 1) + la0)                   # angle between p and q seen from the centre
    wa = 0.5 * (la1 - la0) * wx * al
    cos_t = np.linspace(math.sqrt(1.0 - 1.0 / eta ** 2), 1.0, n_c)
    table = delta_r(2.0 * R * np.sin(al / 2) * s, cos_t, material) * s * s     # (n_alpha, n_c) per mm^2
    ph = (np.arange(n_phi) + 0.5) * math.pi / n_phi                 # half the azimuths: symmetric about y = 0
    rows = np.arange(n_alpha)[:, None]
    out = np.zeros(len(theta_p))

    def entry(cos_i):
        ci = np.clip(cos_i, 0.0, 1.0)
        return np.where(cos_i > 0, ci * (1.0 - fresnel(ci, 1.0, eta)), 0.0), np.sqrt(1.0 - (1.0 - ci * ci) / eta ** 2)

    for k, th in enumerate(theta_p):
        E, ct = entry(np.cos(al)[:, None] * math.cos(th) - np.sin(al)[:, None] * np.cos(ph)[None, :] * math.sin(th))
        u = (ct - cos_t[0]) / (cos_t[1] - cos_t[0])
        j = np.clip(u.astype(int), 0, n_c - 2)
        v = (1.0 - (u - j)) * table[rows, j] + (u - j) * table[rows, j + 1]
        out[k] = 2.0 * np.sum(v * E * (R * R * np.sin(al) * wa)[:, None]) * math.pi / n_phi
        Ep, ctp = entry(np.array(math.cos(th)))
        out[k] += float(Ep) * float(np.interp(ctp, rest_c, rest))
    return out


def sun_ball_exitance(theta_o, D, sigma_a, A, terms=2500, n_theta=600):
    """Exitance at polar angles ``theta_o`` of the ball under a unit sun from +z (module docstring)."""
    kappa = math.sqrt(sigma_a / D)
    x, beta = kappa * R, 2.0 * A * D * kappa
    u, wq = np.polynomial.legendre.leggauss(n_theta)
    th, wth = 0.25 * math.pi * (u + 1.0), 0.25 * math.pi * wq
    n = np.stack([np.sin(th), np.zeros_like(th), np.cos(th)], axis=1)
    ci = np.cos(th)
    power = 2.0 * math.pi * R * R * np.sin(th) * wth * ci * (1.0 - fresnel(ci, 1.0, MATERIAL.eta))
    w = refracted(np.array([0.0, 0.0, -1.0]), n, MATERIAL.eta)
    t, W = np.polynomial.laguerre.laggauss(LINE_POINTS)
    W = float(MATERIAL.albedo_prime[0]) * W
    pts = (R * n[:, None, :] + (t / float(MATERIAL.sigma_t_prime[0]))[None, :, None] * w[:, None, :]).reshape(-1, 3)
    pw = (power[:, None] * W[None, :]).ravel()
    r = np.linalg.norm(pts, axis=1)
    ct, co = pts[:, 2] / r, np.cos(theta_o)
    out = np.zeros(len(theta_o))
    ps_prev, ps, po_prev, po = np.ones_like(ct), ct, np.ones_like(co), co
    for start in range(0, terms, 100):
        ls = np.arange(start, min(terms, start + 100))
        G = bessel_ratio(ls, r, kappa, beta, R)
        for k, l in enumerate(ls):
            if l == 0:
                a, b = ps_prev, po_prev
            elif l == 1:
                a, b = ps, po
            else:
                ps_prev, ps = ps, ((2 * l - 1) * ct * ps - (l - 1) * ps_prev) / l
                po_prev, po = po, ((2 * l - 1) * co * po - (l - 1) * po_prev) / l
                a, b = ps, po
            out += (2 * l + 1) * np.sum(pw * G[k] * a) * b
    return kappa * beta / (4 * math.pi * D * x * x) * out / (2.0 * A)
