"""A painted colour as a medium: the model's own total diffuse reflectance and its inverse (docs/physics.md §17,
eqs. (105)-(106)).

A colour painted on a translucent object is the diffuse reflectance the medium under it must have. The bake's
model returns, on a flat half-space lit at normal incidence, the near-field model of eq. (76) (§15.1: the volume
adds to the lattice exactly what makes the flat case the near-field model), so its total diffuse reflectance per
unit of entering power is

    R_d(alpha'; eta, g) = R^(1)_tot(alpha') + sum_k w_k(alpha') R^(t_k)_tot(alpha')                     (105)

(eq. (71)'s single-scattering total plus the fitted sources' dipole totals, eq. (75) per source): a function of
the reduced albedo alone in optical units, so a mean free path 1/sigma_t' held fixed leaves one unknown per
channel. :func:`model_total_reflectance` evaluates it vectorised over alpha' (the same sums as
:meth:`meshshade.kernels.near_field.NearFieldModel.total`, which does one medium at a time);
:func:`albedo_for_reflectance` solves

    R_d(alpha'; eta, g) = C,   alpha' in (0, ALBEDO_MAX]                                                 (106)

per value by regula falsi (Illinois) in x = log10(1 - alpha') inside the bracket of a monotone table, all values
at once (no Python loop over texels), to 1e-15 in R_d or in x (halving what stalls at rounding level). A colour at or below R_d(0) or at or above the largest reflectance the model reaches (alpha' = ALBEDO_MAX;
:func:`reflectance_range`) is no medium's: a MaterialError.
"""
from __future__ import annotations

import math

import numpy as np

from meshshade.errors import MaterialError
from meshshade.kernels import near_field_table as table
from meshshade.kernels.beam_diffusion import dipole_constants
from meshshade.kernels.fresnel import fresnel_reflectance
from meshshade.kernels.optics import check_eta
from meshshade.kernels.single_scattering import _angles, hg_phase

__all__ = ["model_total_reflectance", "albedo_for_reflectance", "reflectance_range", "ALBEDO_MAX"]

#: the largest reduced albedo a painted medium takes: sigma_a = 1e-6 sigma_t' (the fluence's decay length stays
#: finite, 577 transport lengths; every preset but spectralon, alpha' = 1, lies below it)
ALBEDO_MAX = 1.0 - 1e-6
#: nodes of the monotone table that brackets each root (uniform in x = log10(1 - alpha'), alpha' from 0)
_TABLE_NODES = 1025
#: the solve stops where |R_d - C| <= _R_TOL (a few units in the last place of R_d's own rounding) or the bracket
#: is narrower than _X_TOL in x; at most _MAX_STEPS of regula falsi, then as many halvings for what is left
_R_TOL, _X_TOL, _MAX_STEPS = 1e-15, 1e-15, 60


def _strengths_in_x(eta: float, g: float) -> np.ndarray:
    """(12, K): the fitted sources' strengths at the table's x nodes, interpolated bilinearly in (eta, g) (clamped
    to the grid, as :func:`meshshade.kernels.near_field.near_field_sources` does)."""
    def bracket(nodes, v):
        v = min(max(v, float(nodes[0])), float(nodes[-1]))
        i = int(np.clip(np.searchsorted(nodes, v, side="right") - 1, 0, nodes.size - 2))
        return i, (v - nodes[i]) / (nodes[i + 1] - nodes[i])
    (j, fe), (k, fg) = bracket(table.ETA_NODES, eta), bracket(table.G_NODES, g)
    W = table.WEIGHTS
    return ((1 - fe) * (1 - fg) * W[:, j, k] + (1 - fe) * fg * W[:, j, k + 1]
            + fe * (1 - fg) * W[:, j + 1, k] + fe * fg * W[:, j + 1, k + 1])


def model_total_reflectance(albedo_prime, eta: float, g: float = 0.0) -> np.ndarray:
    """R_d of eq. (105): the bake's model's total diffuse reflectance of a half-space under normal incidence, per
    unit of entering power, at reduced albedos ``albedo_prime`` (array, any shape, in [0, 1]) for index ``eta``
    and anisotropy ``g`` (numbers)."""
    a = np.asarray(albedo_prime, dtype=np.float64)
    if not np.all((a >= 0.0) & (a <= 1.0)):
        raise MaterialError("albedo_prime must be finite and lie in [0, 1]")
    eta = check_eta(float(eta))
    g = float(g)
    if not (math.isfinite(g) and -1.0 < g < 1.0):
        raise MaterialError(f"anisotropy g must be in (-1, 1), got {g!r}")
    flat = a.ravel()
    # single scattering's total, eq. (71) over the exit angles (kernels.single_scattering at cos_t = 1)
    ang, w = _angles(eta)
    c = np.cos(ang)
    f0 = 2.0 * math.pi * hg_phase(-c, g) * (1.0 - fresnel_reflectance(c, eta, 1.0)) * c * np.sin(ang) * w
    sigma_s = flat / (1.0 - g)
    sigma_t = sigma_s + (1.0 - flat)
    single = sigma_s * (((1.0 / (1.0 + c))[None, :] / sigma_t[:, None]) @ f0)
    # the fitted sources' strengths, linear in x = log10(1 - alpha') between the grid's nodes (clamped)
    x = np.log10(np.maximum(1.0 - flat, 1e-300))
    Wx = _strengths_in_x(eta, g)
    strengths = np.stack([np.interp(x, table.X_NODES, Wx[:, k]) for k in range(Wx.shape[1])], axis=1)
    # each source's dipole total, eq. (75) per source: C_E (e_r + e_v) / 2 + C_phi (e_r - e_v) / (2 D mu)
    k = dipole_constants(flat, eta, "better")
    D, mu, zb = (np.broadcast_to(np.asarray(v, dtype=np.float64), flat.shape)[:, None] for v in (k.D, k.mu, k.z_b))
    cphi = np.broadcast_to(np.asarray(k.c_phi, dtype=np.float64), flat.shape)[:, None]
    cE = np.broadcast_to(np.asarray(k.c_E, dtype=np.float64), flat.shape)[:, None]
    t = table.DEPTHS[None, :]
    e_r, e_v = np.exp(-mu * t), np.exp(-mu * (t + 2.0 * zb))
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(mu > 0, (e_r - e_v) / (2.0 * D * np.where(mu > 0, mu, 1.0)), 2.0 * zb / (2.0 * D))
    multiple = np.sum(strengths * (cE * 0.5 * (e_r + e_v) + cphi * phi), axis=1)
    return (single + multiple).reshape(a.shape)


def reflectance_range(eta: float, g: float = 0.0) -> tuple[float, float]:
    """(R_d at alpha' = 0, R_d at ALBEDO_MAX): the colours a painted medium of index ``eta`` and anisotropy ``g``
    can have. The lower end is not quite 0: below the grid's last node (alpha' = 0.018) the fitted sources are that
    node's (eq. (76), clamped), which return some light whatever the albedo (2e-5 at eta 1.3; 0.023 before the
    table reached below alpha' = 0.5)."""
    lo, hi = model_total_reflectance(np.array([0.0, ALBEDO_MAX]), eta, g)
    return float(lo), float(hi)


def _x_of(albedo_prime):
    return np.log10(1.0 - albedo_prime)


def albedo_for_reflectance(reflectance, eta: float, g: float = 0.0) -> np.ndarray:
    """alpha' with R_d(alpha'; eta, g) = ``reflectance`` (eq. (106)), per value (array, any shape; each value
    solved once however often it occurs). MaterialError, naming the range, for a value <= R_d(0), >= the largest
    reachable reflectance (:func:`reflectance_range`) or not finite."""
    C = np.asarray(reflectance, dtype=np.float64)
    r_min, r_max = reflectance_range(eta, g)
    bad = ~((C > r_min) & (C < r_max))
    if bad.any():
        v = float(C[bad].flat[0])
        raise MaterialError(f"a painted colour must lie in ({r_min:.4f}, {r_max:.4f}) per channel (eta "
                            f"{float(eta):g}: no medium of the model reflects less or more), got {v!r}")
    values, inverse = np.unique(C.ravel(), return_inverse=True)
    x_lo = float(_x_of(ALBEDO_MAX))                       # x decreases as alpha' grows
    xs = np.linspace(0.0, x_lo, _TABLE_NODES)
    R = model_total_reflectance(1.0 - 10.0 ** xs, eta, g)
    if not np.all(np.diff(R) > 0):
        raise MaterialError(f"the model's total reflectance is not monotone in the albedo at eta {float(eta):g}, "
                            f"g {float(g):g}")
    i = np.clip(np.searchsorted(R, values, side="right") - 1, 0, _TABLE_NODES - 2)
    lo, hi = xs[i].copy(), xs[i + 1].copy()                 # R(lo) <= C < R(hi)
    f_lo, f_hi = R[i] - values, R[i + 1] - values
    x = lo.copy()
    todo = np.arange(values.size)
    last = np.zeros(values.size, dtype=np.int8)             # the side moved last (Illinois)
    for _ in range(_MAX_STEPS):                              # regula falsi, Illinois-modified, on the open ones
        if todo.size == 0:
            break
        l, h, fl, fh = lo[todo], hi[todo], f_lo[todo], f_hi[todo]
        xm = np.clip((l * fh - h * fl) / (fh - fl), np.minimum(l, h), np.maximum(l, h))
        fm = model_total_reflectance(1.0 - 10.0 ** xm, eta, g) - values[todo]
        x[todo] = xm
        left = fm <= 0.0
        lo[todo] = np.where(left, xm, l)
        f_lo[todo] = np.where(left, fm, np.where(last[todo] == -1, 0.5 * fl, fl))
        hi[todo] = np.where(left, h, xm)
        f_hi[todo] = np.where(left, np.where(last[todo] == 1, 0.5 * fh, fh), fm)
        last[todo] = np.where(left, 1, -1)
        done = (np.abs(fm) <= _R_TOL) | (np.abs(hi[todo] - lo[todo]) <= _X_TOL)
        todo = todo[~done]
    for _ in range(_MAX_STEPS):                              # what regula falsi left (rounding-level stalls): halved
        if todo.size == 0:
            break
        mid = 0.5 * (lo[todo] + hi[todo])
        fm = model_total_reflectance(1.0 - 10.0 ** mid, eta, g) - values[todo]
        x[todo] = mid
        left = fm <= 0.0
        lo[todo] = np.where(left, mid, lo[todo])
        hi[todo] = np.where(left, hi[todo], mid)
        done = (np.abs(fm) <= _R_TOL) | (np.abs(hi[todo] - lo[todo]) <= _X_TOL)
        todo = todo[~done]
    if todo.size:
        raise MaterialError(f"the painted colours' albedos did not converge ({todo.size} values)")
    return (1.0 - 10.0 ** x)[inverse].reshape(C.shape)
