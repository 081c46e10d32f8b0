"""References for `meshshade bench`: the best available exitance of each benchmark scene, and its error metrics.

Three kinds, all per unit light (beam power 1 W, directional irradiance 1 W/mm^2), grey material channel 0:

* ``exact`` on a sphere under a beam: ``M(x) = F_t(cos_i) R_sph(theta)``, the exact sphere series
  (kernels/sphere.py) at the great-circle angle ``theta`` between x and the beam's entry point on the *exact*
  sphere (ray-sphere intersection, exact normal for the Fresnel factor).
* ``exact`` on a sphere under a directional light: the exact solution integrates the sphere series over the lit
  hemisphere with the power that enters there, as light/samples.py defines it (``E cos F_t(cos)`` per unit area):

      M(beta) = E int_0^pi R_sph(gamma) R0^2 sin(gamma) [ int_0^2pi w(cos t) dpsi ] dgamma,
      cos t = cos(beta) cos(gamma) + sin(beta) sin(gamma) cos(psi),     w(c) = max(c, 0) F_t(c),

  in polar coordinates (gamma, psi) centred on the exit point x (beta: angle of x from the point facing the
  light). The kernel is radial there, so the sharp peak of R_sph at gamma = 0 is integrated by composite
  Gauss-Legendre panels graded in s = R0 gamma (0.25, 0.5, 1, 2, 4, ... mm, 24 nodes each) and the smooth
  weight w by the periodic trapezoid rule in psi (256 nodes over the period; w ~ c^2 at the terminator). M is
  tabulated on 289 angles beta (denser near the terminator) and interpolated with a cubic spline (measured
  within 4e-6 of the direct quadrature with 512 psi nodes). Check: its integral over the sphere equals the
  entering power times the closed-form total reflectance ``alpha' T`` (sphere_total_reflectance): measured
  within 1e-8 for R0 = 5, 20 and 100 mm; tests/bench/test_bench.py asserts 1e-6.
* ``exact`` on a long capped cylinder under a beam: the exact infinite-cylinder kernel (kernels/cylinder.py) at
  the vertex's angle and axial offset from the entry point, on side vertices only (caps and rims excluded; the
  cylinder is long enough that the default cutoff never reaches a cap).
* ``mc``: a Monte Carlo run (meshshade.montecarlo.simulation.simulate, public API only) with its batch-means standard
  errors. Per-vertex MC values are too noisy to compare one by one, so errors are taken on *patches*: faces
  grouped by a grid of cell ``patch_mm`` over their centroids; the model's patch power is the integral of its
  linearly interpolated exitance, ``sum_f area_f mean(M at f's corners)``, the reference's is the MC face power
  summed (stderr: faces added in quadrature).

Where the statistics are taken (``mask``): exitance above ``EXACT_FLOOR`` (1e-4) of the reference's peak for
exact references, outside the fan of the entry triangle for beams (there a point beam's peak is not resolved by
any per-vertex value), and for MC, patch density above ``MC_FLOOR`` (1e-3) of its peak and relative standard
error below ``MC_MAX_REL_STDERR`` (5 %).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshshade.kernels.cylinder import cylinder_exact_profile
from meshshade.kernels.fresnel import fresnel_transmittance_entry
from meshshade.kernels.sphere import sphere_series_profile, sphere_total_reflectance
from meshshade.light import BeamLight
from meshshade.raycast import make_scene

EXACT_FLOOR = 1e-4
MC_FLOOR = 1e-3
MC_MAX_REL_STDERR = 0.05
#: series tolerance of the exact references (well below any knob value)
REFERENCE_RTOL = 1e-13


# ------------------------------------------------------------------------------------------------ exact kernels
def _channel(material):
    ch = material.channel(0)
    return float(ch["sigma_t_prime"]), {"albedo_prime": float(ch["albedo_prime"]), "eta": float(ch["eta"])}


def _gl_panels(s_max: float, n: int = 24):
    """Nodes and weights of composite Gauss-Legendre on [0, s_max] with panels 0.25, 0.5, 1, 2, 4 ... mm."""
    edges = [0.0, 0.25]
    while edges[-1] < s_max:
        edges.append(min(2.0 * edges[-1], s_max))
    x, w = np.polynomial.legendre.leggauss(n)
    a, b = np.array(edges[:-1]), np.array(edges[1:])
    nodes = (0.5 * (a + b))[:, None] + (0.5 * (b - a))[:, None] * x[None, :]
    weights = (0.5 * (b - a))[:, None] * w[None, :]
    return nodes.ravel(), weights.ravel()


def sphere_beam_exitance(theta, *, R_mm: float, material, cos_i: float = 1.0, power: float = 1.0):
    """Exitance [W/mm^2] at angle ``theta`` from a beam's entry point on the exact sphere: P F_t(cos_i) R_sph."""
    st, par = _channel(material)
    th = np.clip(np.asarray(theta, dtype=np.float64), 0.0, np.pi)
    ft = float(fresnel_transmittance_entry(cos_i, par["eta"]))
    return power * ft * sphere_series_profile(th, R0_opt=R_mm * st, rtol=REFERENCE_RTOL, **par) * st * st


def sphere_directional_exitance(beta, *, R_mm: float, material, irradiance: float = 1.0, n_psi: int = 128):
    """Exitance [W/mm^2] of the exact sphere under a directional light at angle ``beta`` from the point facing it.

    Integrates the exact sphere series over the lit hemisphere (module docstring); the psi integrand is even, so
    the trapezoid rule runs over [0, pi] with ``n_psi + 1`` nodes (equivalent to 2 n_psi over the period).
    Gamma nodes where the kernel is below 1e-15 of its peak are dropped. ``beta`` (k,) rad.
    """
    st, par = _channel(material)
    s, ws = _gl_panels(np.pi * R_mm)
    gam = s / R_mm
    kern = sphere_series_profile(gam, R0_opt=R_mm * st, rtol=REFERENCE_RTOL, **par) * st * st
    keep = kern > 1e-15 * kern.max()
    gam, wg = gam[keep], (ws * kern * R_mm * np.sin(gam))[keep]      # dA = R0 sin(gamma) ds dpsi
    psi = np.linspace(0.0, np.pi, n_psi + 1)
    wpsi = np.full(psi.size, np.pi / n_psi)
    wpsi[[0, -1]] *= 0.5
    wpsi *= 2.0                                                       # both halves of the period
    cp = np.cos(psi)
    beta = np.atleast_1d(np.asarray(beta, dtype=np.float64))
    out = np.empty(beta.shape)
    cg, sg = np.cos(gam), np.sin(gam)
    for a in range(0, beta.size, 16):
        b = beta[a:a + 16]
        c = np.cos(b)[:, None, None] * cg[None, :, None] + np.sin(b)[:, None, None] * sg[None, :, None] * cp
        c = np.clip(c, 0.0, 1.0)
        w = c * fresnel_transmittance_entry(c, par["eta"])
        out[a:a + 16] = (w @ wpsi) @ wg
    return irradiance * out


def sphere_directional_table(*, R_mm: float, material):
    """A cubic spline beta -> exitance of :func:`sphere_directional_exitance`: 193 angles over [0, pi] plus 97
    within 0.15 rad of the terminator (where M falls over a few transport lengths / R0)."""
    from scipy.interpolate import CubicSpline  # lazy: ~0.1-0.3 s on every CLI start; only this table needs it

    beta = np.unique(np.concatenate([np.linspace(0.0, np.pi, 193), np.pi / 2 + np.linspace(-0.15, 0.15, 97)]))
    return CubicSpline(beta, sphere_directional_exitance(beta, R_mm=R_mm, material=material))


def sphere_directional_energy(*, R_mm: float, material, irradiance: float = 1.0) -> float:
    """Total exitant power [W] of the exact sphere under a directional light: entering power x alpha' T.

    Entering power = E 2 pi R0^2 int_0^1 c F_t(c) dc (Gauss-Legendre, 64 nodes); alpha' T in closed form."""
    st, par = _channel(material)
    x, w = np.polynomial.legendre.leggauss(64)
    c = 0.5 * (x + 1.0)
    mean_cft = float(np.sum(0.5 * w * c * fresnel_transmittance_entry(c, par["eta"])))
    entering = irradiance * 2.0 * np.pi * R_mm**2 * mean_cft
    return entering * float(sphere_total_reflectance(R0_opt=R_mm * st, **par))


# ------------------------------------------------------------------------------------------------ reference objects
@dataclass
class Reference:
    """The reference exitance of one scene at one mesh resolution.

    kind : "exact" or "mc"; point : callable (k, 3) mm -> (k,) W/mm^2 (exact kinds only, for pixels);
    vertex : (n,) W/mm^2 at the vertices (exact; for mc the MC estimate); mask : (n,) bool vertices where the
    statistics are taken (exact); energy : total exitant power [W] (None: only the masked integral is known);
    peak : W/mm^2 scale of the floor; entry_fan : (n,) bool vertices of the faces around the entry triangle;
    patch_* : MC patches (face -> patch id, power, stderr, mask); stderr_median : median relative stderr of
    the MC over the evaluated patches; seconds : time to build.
    """

    kind: str
    vertex: np.ndarray
    mask: np.ndarray
    peak: float
    energy: float | None = None
    point: object = None
    entry_fan: np.ndarray | None = None
    patch_id: np.ndarray | None = None
    patch_power: np.ndarray | None = None
    patch_stderr: np.ndarray | None = None
    patch_mask: np.ndarray | None = None
    stderr_median: float | None = None
    seconds: float = 0.0


def entry_fan(mesh, light) -> np.ndarray | None:
    """(n,) bool: vertices of the faces touching the corners of the face a beam enters (None for other lights)."""
    if not isinstance(light, BeamLight):
        return None
    hits = make_scene(mesh.vertices, mesh.faces).first_hit(np.array([light.origin]), np.array([light.direction]))
    f = int(hits.face[0])
    corners = mesh.faces[f]
    fan = np.zeros(mesh.n_vertices, bool)
    fan[mesh.faces[np.any(np.isin(mesh.faces, corners), axis=1)].ravel()] = True
    return fan


def _ray_sphere(origin, direction, R):
    o, d = np.asarray(origin, float), np.asarray(direction, float)
    b = o @ d
    t = -b - np.sqrt(b * b - (o @ o - R * R))
    p = o + t * d
    return p / R, float(-(p / R) @ d)


def exact_sphere_reference(mesh, light, *, R_mm: float, material) -> Reference:
    """Exact reference of a sphere of radius ``R_mm`` centred at the origin under a beam or directional light."""
    if isinstance(light, BeamLight):
        e, cos_i = _ray_sphere(light.origin, light.direction, R_mm)

        def point(p):
            u = np.asarray(p, float) / np.linalg.norm(p, axis=1, keepdims=True)
            th = 2.0 * np.arcsin(np.clip(0.5 * np.linalg.norm(u - e, axis=1), 0.0, 1.0))  # no acos rounding at 0
            return sphere_beam_exitance(th, R_mm=R_mm, material=material, cos_i=cos_i, power=light.power)

        st, par = _channel(material)
        peak = float(point(e[None, :] * R_mm)[0])
        energy = light.power * float(fresnel_transmittance_entry(cos_i, par["eta"])) * float(
            sphere_total_reflectance(R0_opt=R_mm * st, **par))
    else:
        toward = -np.asarray(light.direction, float)
        spline = sphere_directional_table(R_mm=R_mm, material=material)

        def point(p):
            u = np.asarray(p, float) / np.linalg.norm(p, axis=1, keepdims=True)
            return light.irradiance * spline(np.arccos(np.clip(u @ toward, -1.0, 1.0)))

        peak = float(light.irradiance * spline(0.0))
        energy = light.irradiance * sphere_directional_energy(R_mm=R_mm, material=material)
    vertex = point(mesh.vertices)
    fan = entry_fan(mesh, light)
    mask = vertex >= EXACT_FLOOR * peak
    if fan is not None:
        mask &= ~fan
    return Reference("exact", vertex, mask, peak, energy=energy, point=point, entry_fan=fan)


def exact_cylinder_reference(mesh, light, *, R_mm: float, length_mm: float, material) -> Reference:
    """Infinite-cylinder reference on the side vertices of a capped cylinder along z (beam lights only)."""
    st, par = _channel(material)
    o, d = np.asarray(light.origin, float), np.asarray(light.direction, float)
    # entry: ray against the infinite cylinder x^2 + y^2 = R^2
    a, b, c = d[0] ** 2 + d[1] ** 2, o[0] * d[0] + o[1] * d[1], o[0] ** 2 + o[1] ** 2 - R_mm**2
    t = (-b - np.sqrt(b * b - a * c)) / a
    p = o + t * d
    n = np.array([p[0], p[1], 0.0]) / R_mm
    ft = float(fresnel_transmittance_entry(float(-(n @ d)), par["eta"])) * light.power
    th_e = np.arctan2(p[1], p[0])
    reach = 4.0 * R_mm + 60.0  # beyond the largest cutoff tolerance of the bench (1e-6: 64 mm for skin-like)

    def point(q):
        q = np.asarray(q, float)
        th = np.abs(np.mod(np.arctan2(q[:, 1], q[:, 0]) - th_e + np.pi, 2.0 * np.pi) - np.pi)
        dz = np.abs(q[:, 2] - p[2])
        out = np.zeros(len(q))
        near = np.hypot(R_mm * th, dz) <= reach
        if np.any(near):
            out[near] = np.maximum(cylinder_exact_profile(th[near], dz[near] * st, R0_opt=R_mm * st, rtol=1e-9,
                                                          **par), 0.0) * st * st * ft
        return out

    V = mesh.vertices
    side = (np.abs(np.hypot(V[:, 0], V[:, 1]) - R_mm) < 1e-9 * R_mm) & (np.abs(V[:, 2]) < 0.5 * length_mm * (1 - 1e-9))
    vertex = np.zeros(mesh.n_vertices)
    vertex[side] = point(V[side])
    peak = float(point(p[None, :])[0])
    fan = entry_fan(mesh, light)
    mask = side & (vertex >= EXACT_FLOOR * peak) & ~fan
    return Reference("exact", vertex, mask, peak, energy=None, point=point, entry_fan=fan)


def face_patches(mesh, patch_mm: float) -> np.ndarray:
    """(m,) int: patch id of each face, a grid of cell ``patch_mm`` over the face centroids."""
    cen = mesh.vertices[mesh.faces].mean(axis=1)
    key = np.floor((cen - cen.min(axis=0)) / patch_mm).astype(np.int64)
    _, inv = np.unique(key, axis=0, return_inverse=True)
    return inv.reshape(-1)


def mc_reference(mesh, light, mc, *, patch_mm: float, channel: int = 0) -> Reference:
    """Patch reference from an MCResult ``mc`` (``channel``, default 0)."""
    c = int(channel)
    pid = face_patches(mesh, patch_mm)
    fan = entry_fan(mesh, light)
    use = np.ones(mesh.n_faces, bool) if fan is None else ~np.any(fan[mesh.faces], axis=1)
    n_p = int(pid.max()) + 1
    w = np.where(use, 1.0, 0.0)
    power = np.bincount(pid, weights=w * mc.face_power[:, c], minlength=n_p)
    var = np.bincount(pid, weights=w * mc.face_power_stderr[:, c] ** 2, minlength=n_p)
    area = np.bincount(pid, weights=w * mesh.face_areas, minlength=n_p)
    stderr = np.sqrt(var)
    with np.errstate(divide="ignore", invalid="ignore"):
        density = np.where(area > 0, power / area, 0.0)
        rel = np.where(power > 0, stderr / power, np.inf)
    peak = float(density.max())
    pmask = (density >= MC_FLOOR * peak) & (rel <= MC_MAX_REL_STDERR) & (area > 0)
    return Reference("mc", np.asarray(mc.radiance[:, c], float), np.zeros(mesh.n_vertices, bool), peak,
                     energy=float(mc.face_power[:, c].sum()), entry_fan=fan,
                     patch_id=np.where(use, pid, -1), patch_power=power, patch_stderr=stderr, patch_mask=pmask,
                     stderr_median=float(np.median(rel[pmask])) if np.any(pmask) else None)


# ------------------------------------------------------------------------------------------------ metrics
def _stats(rel) -> tuple[float, float]:
    r = np.abs(rel)
    return (float(r.max()), float(r.mean())) if r.size else (float("nan"), float("nan"))


def vertex_errors(mesh, M, ref: Reference) -> dict:
    """Errors of per-vertex exitance ``M`` (n,) against ``ref``: max and mean |relative error| over the mask
    (vertices, or MC patches) and the relative error of the total exitant power (global where the reference
    knows it, else over the mask, area-weighted). For MC also ``resolved_frac``: the fraction of patches where
    the difference exceeds twice the MC standard error (the rest is within the reference's noise)."""
    M = np.asarray(M, float)
    A = mesh.vertex_areas
    if ref.kind == "mc":
        face_p = mesh.face_areas * M[mesh.faces].mean(axis=1)
        ok = ref.patch_id >= 0
        n_p = ref.patch_power.size
        model = np.bincount(ref.patch_id[ok], weights=face_p[ok], minlength=n_p)
        sel = ref.patch_mask
        emax, emean = _stats(model[sel] / ref.patch_power[sel] - 1.0)
        total = float(np.sum(M * A))
        resolved = np.abs(model[sel] - ref.patch_power[sel]) > 2.0 * ref.patch_stderr[sel]
        return {"error_max": emax, "error_mean": emean, "error_energy": total / ref.energy - 1.0,
                "n_eval": int(sel.sum()), "resolved_frac": float(resolved.mean()) if resolved.size else None}
    sel = ref.mask
    emax, emean = _stats(M[sel] / ref.vertex[sel] - 1.0)
    if ref.energy is not None:
        energy = float(np.sum(M * A)) / ref.energy - 1.0
    else:
        energy = float(np.sum((M * A)[sel]) / np.sum((ref.vertex * A)[sel])) - 1.0
    return {"error_max": emax, "error_mean": emean, "error_energy": energy, "n_eval": int(sel.sum())}


def pixel_errors(M_pix, ref_pix, peak: float) -> dict:
    """Errors over pixels whose reference exitance is above EXACT_FLOOR x peak (no fan exclusion: resolving the
    beam's peak between vertices is what per-pixel rendering is for)."""
    sel = ref_pix >= EXACT_FLOOR * peak
    emax, emean = _stats(M_pix[sel] / ref_pix[sel] - 1.0)
    return {"error_max": emax, "error_mean": emean, "error_energy": float(np.sum(M_pix[sel]) / np.sum(ref_pix[sel]))
            - 1.0, "n_eval": int(sel.sum())}
