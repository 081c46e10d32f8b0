"""Monte Carlo on exact shapes: the half-space, the sphere, the infinite cylinder and their concave counterparts (a
spherical cavity and a cylindrical bore: the medium outside a ball or a cylinder), with exact exit distances.

The reference for reflectance *profiles* (``meshshade profile --models mc``). A pencil beam enters at normal
incidence; the walk is that of the mesh engine (MCML conventions, :mod:`meshshade.montecarlo.loops`: free paths
with the full sigma_t = sigma_s + sigma_a, sigma_s = sigma_s' / (1 - g), Henyey-Greenstein scattering, implicit
absorption with Russian roulette, Fresnel reflection at the boundary chosen by a random draw), but the boundary is
the exact surface, found in closed form, and every exit point's geodesic distance from the entry point is exact:

* half-space ``z < 0``, entry at the origin: s = sqrt(x^2 + y^2);
* sphere of radius R, entry at the north pole: s = R * (angle from the pole);
* cylinder of radius R about the z axis, entry at (R, 0, 0): the surface unrolls isometrically onto a plane, so
  with u = R * (angle around the axis from the entry, in (-pi, pi]) and v = z, s = sqrt(u^2 + v^2), and the exit
  azimuth from the first principal direction (around the axis) is atan2(|v|, |u|) (the profile is symmetric
  under u -> -u and v -> -v);
* spherical cavity (medium outside the ball of radius R, k1 = k2 = -1/R) and cylindrical bore (medium outside the
  cylinder, k1 = 0, k2 = -1/R around the axis): the entry points and geodesics of the sphere and cylinder. A photon
  that leaves the medium is tallied where it leaves; it does not cross the hollow and re-enter (the profile is the
  exitance due to the one source, as the diffusion solutions compute it).

So the first millimetre is as exact as the rest: nothing is interpolated from vertices (the mesh engine's ring
tallies read vertex geodesics, which smear the region within an edge length or two of the source). Exits are also
tallied by scattering order, so the singly scattered part is available on its own (it has a closed-form check on
the half-space). Every photon owns a counter-based random stream keyed by (seed, channel, photon index), so a run
is reproducible for a given ``seed`` and independent of the thread count; the standard errors are batch means over
contiguous blocks of photons.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from meshshade.errors import ParameterError
from meshshade.materials import Material
from meshshade.montecarlo.loops import _OPTS, _uniform, fresnel_out, photon_key, scatter_s, stream_base
from meshshade.montecarlo.sampling import ROULETTE_BOOST, ROULETTE_THRESHOLD
from meshshade.montecarlo.simulation import DEFAULT_BATCHES, batch_stats

__all__ = ["SHAPE_KINDS", "ShapeProfile", "shape_mc_profile", "shape_mc_profiles",
           "ring_halfwidth", "ring_area", "walk_shape"]

#: the exact shapes, in the order of the kernel's ``kind`` code
SHAPE_KINDS = ("plane", "sphere", "cylinder", "cavity", "bore")
#: the concave shapes and the convex shape whose geodesics they share
HOLLOW_OF = {"cavity": "sphere", "bore": "cylinder"}
#: a photon still inside after this many free paths is counted as lost (never seen with albedo < 1)
MAX_EVENTS = 10_000_000
#: photons per call of the kernel
CHUNK = 1 << 18
#: default half-width of a cylinder's azimuthal sector [deg]
SECTOR_DEG = 15.0


@njit(inline="always", **_OPTS)
def _to_boundary(kind, R, x, y, z, dx, dy, dz):
    """Distance along (dx, dy, dz) from (x, y, z) inside to the surface (inf when the ray never meets it)."""
    if kind == 0:
        return -z / dz if dz > 0.0 else np.inf
    if kind == 1:
        b = x * dx + y * dy + z * dz
        c = x * x + y * y + z * z - R * R
        disc = max(b * b - c, 0.0)
        return max(-b + math.sqrt(disc), 0.0)
    if kind == 3:   # outside the ball: the nearer root, if the ray meets the ball at all
        b = x * dx + y * dy + z * dz
        if b >= 0.0:
            return np.inf
        c = max(x * x + y * y + z * z - R * R, 0.0)
        disc = b * b - c
        return -b - math.sqrt(disc) if disc > 0.0 else np.inf
    a = dx * dx + dy * dy
    if a < 1e-300:
        return np.inf
    b = x * dx + y * dy
    c = x * x + y * y - R * R
    if kind == 4:   # outside the cylinder
        if b >= 0.0:
            return np.inf
        c = max(c, 0.0)
        disc = b * b - a * c
        return (-b - math.sqrt(disc)) / a if disc > 0.0 else np.inf
    disc = max(b * b - a * c, 0.0)
    return max((-b + math.sqrt(disc)) / a, 0.0)


@njit(parallel=True, **_OPTS)
def walk_shape(kind, R, sigma_t, albedo, g, eta, base, start, n, thr, boost, max_events, ex, ey, ez, ew, order,
               sin_t=0.0):
    """Photons ``start .. start + n - 1``: their exit point (ex, ey, ez), weight ``ew`` (0: absorbed, roulette or
    lost) and scattering ``order`` (-1: lost after ``max_events`` free paths), per photon slot ``0 .. n - 1``.
    On the plane the photons start along the refracted direction (sin_t, 0, -cos_t)."""
    for j in prange(n):
        key = photon_key(base, start + j)
        c = np.uint64(0)
        if kind == 0:
            x, y, z, dx, dy, dz = 0.0, 0.0, 0.0, sin_t, 0.0, -math.sqrt(1.0 - sin_t * sin_t)
        elif kind == 1:
            x, y, z, dx, dy, dz = 0.0, 0.0, R, 0.0, 0.0, -1.0
        elif kind == 2:
            x, y, z, dx, dy, dz = R, 0.0, 0.0, -1.0, 0.0, 0.0
        elif kind == 3:
            x, y, z, dx, dy, dz = 0.0, 0.0, R, 0.0, 0.0, 1.0
        else:
            x, y, z, dx, dy, dz = R, 0.0, 0.0, 1.0, 0.0, 0.0
        w = 1.0
        k = 0
        ew[j] = 0.0
        order[j] = 0
        done = False
        for _ in range(max_events):
            u, c = _uniform(key, c)
            s = -math.log(1.0 - u) / sigma_t
            t = _to_boundary(kind, R, x, y, z, dx, dy, dz)
            if s < t:
                x, y, z, dx, dy, dz, w, c, _ab, alive = scatter_s(x, y, z, dx, dy, dz, w, s, key, c, thr, albedo, g,
                                                                  boost)
                k += 1
                if not alive:
                    done = True
                    break
                continue
            x += t * dx
            y += t * dy
            z += t * dz
            if kind == 0:
                z = 0.0
                nx, ny, nz = 0.0, 0.0, 1.0
            elif kind == 1 or kind == 3:   # the outward normal of the medium: -r/R in a cavity
                r = math.sqrt(x * x + y * y + z * z)
                x, y, z = x * R / r, y * R / r, z * R / r
                sg = 1.0 if kind == 1 else -1.0
                nx, ny, nz = sg * x / R, sg * y / R, sg * z / R
            else:
                r = math.sqrt(x * x + y * y)
                x, y = x * R / r, y * R / r
                sg = 1.0 if kind == 2 else -1.0
                nx, ny, nz = sg * x / R, sg * y / R, 0.0
            cos_i = dx * nx + dy * ny + dz * nz
            u, c = _uniform(key, c)
            if u < fresnel_out(cos_i, eta):   # reflected back inside (total internal reflection included)
                dx -= 2.0 * cos_i * nx
                dy -= 2.0 * cos_i * ny
                dz -= 2.0 * cos_i * nz
                inv = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
                dx, dy, dz = dx * inv, dy * inv, dz * inv
                continue
            ex[j], ey[j], ez[j], ew[j] = x, y, z, w
            order[j] = k
            done = True
            break
        if not done:
            order[j] = -1


def exit_coordinates(kind: str, R: float, x, y, z):
    """(geodesic distance s [mm], azimuth from the first principal direction [rad] in [0, pi/2]) of exit points."""
    if kind == "plane":
        return np.hypot(x, y), np.arctan2(np.abs(y), np.abs(x))
    kind = HOLLOW_OF.get(kind, kind)
    if kind == "sphere":
        return R * np.arctan2(np.hypot(x, y), z), np.arctan2(np.abs(y), np.abs(x))
    u = R * np.arctan2(y, x)
    return np.hypot(u, z), np.arctan2(np.abs(z), np.abs(u))


def ring_halfwidth(distances_mm, material: Material):
    """Half-width [mm] of the ring tallied around each distance: max(0.1 s, 0.05 / min sigma_t') (as the mesh
    profile's)."""
    s = np.asarray(distances_mm, dtype=np.float64)
    return np.maximum(0.1 * s, 0.05 / float(np.min(material.sigma_t_prime)))


def ring_area(kind: str, R: float | None, a, b, sector=None):
    """Surface area [mm^2] between geodesic distances a < b (arrays) from the entry point; on the cylinder within
    the folded azimuth window ``sector`` = (lo, hi) rad in [0, pi/2] (four mirror images)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    kind = HOLLOW_OF.get(kind, kind)
    if kind == "plane":
        return np.pi * (b * b - a * a)
    if kind == "sphere":
        return 2.0 * np.pi * R * R * (np.cos(a / R) - np.cos(np.minimum(b / R, np.pi)))
    lo, hi = sector
    return 4.0 * (hi - lo) * 0.5 * (b * b - a * a)


@dataclass(frozen=True)
class ShapeProfile:
    """Result of :func:`shape_mc_profile`: per channel (r, g, b) and distance, the ring-averaged reflectance per
    unit entering power ``reflectance`` [mm^-2] with its ``stderr``, its singly scattered part ``single`` (and
    ``single_stderr``), the rings' ``lo``/``hi`` edges [mm], and the total diffuse reflectance per unit entering
    power ``total`` (and ``total_stderr``), ``lost`` photons, ``photons`` per channel, ``seconds``."""

    shape: str
    radius_mm: float | None
    distances_mm: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    azimuth_deg: float
    reflectance: np.ndarray
    stderr: np.ndarray
    single: np.ndarray
    single_stderr: np.ndarray
    total: np.ndarray
    total_stderr: np.ndarray
    lost: int
    photons: int
    seconds: float

    def __repr__(self) -> str:
        return (f"<ShapeProfile {self.shape}" + (f" R={self.radius_mm:g} mm" if self.radius_mm else "")
                + f": {self.distances_mm.size} rings, {self.photons} photons per channel, total diffuse "
                + "/".join(f"{t:.4f}" for t in self.total) + f" (±{np.max(self.total_stderr):.1g}), "
                f"{self.seconds:.3g} s>")


def _check(shape_kind, radius_mm, s, lo, hi, azimuth, photons, n_batches, sector_deg):
    like = HOLLOW_OF.get(shape_kind, shape_kind)
    if shape_kind not in SHAPE_KINDS:
        raise ParameterError(f"Monte Carlo profiles are exact on {', '.join(SHAPE_KINDS)}; got shape {shape_kind!r} "
                             "(use `meshshade mc` on a mesh for other geometry)")
    if shape_kind != "plane" and not (radius_mm is not None and math.isfinite(radius_mm) and radius_mm > 0):
        raise ParameterError(f"a {shape_kind} needs a radius > 0 mm, got {radius_mm!r}")
    if not (isinstance(photons, (int, np.integer)) and photons >= n_batches):
        raise ParameterError(f"photons must be an integer >= the {n_batches} batches, got {photons!r}")
    if like == "sphere" and np.any(s > np.pi * radius_mm):
        raise ParameterError(f"distances beyond half the circumference ({np.pi * radius_mm:.6g} mm) do not exist "
                             f"on this sphere")
    if like == "cylinder" and not 0.0 < sector_deg <= 45.0:
        raise ParameterError(f"the cylinder's sector half-width must be in (0, 45] deg, got {sector_deg!r}")


def shape_mc_profile(material: Material, distances_mm, *, shape: str = "plane", radius_mm: float | None = None,
                     photons: int = 1_000_000, seed: int = 0, azimuth_deg: float = 0.0, halfwidth_mm=None,
                     n_batches: int = DEFAULT_BATCHES, sector_deg: float = SECTOR_DEG,
                     progress=None, incidence_deg: float = 0.0) -> ShapeProfile:
    """Ring-averaged reflectance profile by Monte Carlo on an exact ``shape`` ("plane", "sphere", "cylinder",
    "cavity", "bore"; the last two are the medium outside a ball and outside a cylinder): ``photons`` per channel
    (channels with equal coefficients share one run), a unit pencil beam entering at normal incidence
    (``reflectance`` is per unit *entering* power; on the plane at ``incidence_deg`` from the normal in [0, 90),
    refracted by Snell's law, rings still centred on the entry point), rings [max(s - h, 0), s + h] with
    h = ``halfwidth_mm`` (default :func:`ring_halfwidth`); on the cylinder and bore only exits within ``sector_deg``
    of ``azimuth_deg`` (from the direction around the axis, folded into [0, 90] deg by symmetry) count, and a ring
    whose sector reaches half the girth around the cylinder (where the unrolled surface would overlap itself) is NaN;
    on the sphere and cavity the last ring may be the cap around the antipode. ``progress``: a callable(photons
    done) or None. :func:`shape_mc_profiles` tallies several azimuths of one run.
    """
    return shape_mc_profiles(material, distances_mm, shape=shape, radius_mm=radius_mm, photons=photons, seed=seed,
                             azimuths_deg=(azimuth_deg,), halfwidth_mm=halfwidth_mm, n_batches=n_batches,
                             sector_deg=sector_deg, progress=progress, incidence_deg=incidence_deg)[0]


def shape_mc_profiles(material: Material, distances_mm, *, shape: str = "plane", radius_mm: float | None = None,
                      photons: int = 1_000_000, seed: int = 0, azimuths_deg=(0.0,), halfwidth_mm=None,
                      n_batches: int = DEFAULT_BATCHES, sector_deg: float = SECTOR_DEG,
                      progress=None, incidence_deg: float = 0.0) -> list[ShapeProfile]:
    """:func:`shape_mc_profile` for several azimuths (``azimuths_deg``, one :class:`ShapeProfile` each) tallied from
    the same photons: on the plane, sphere and cavity the profiles are identical; on the cylinder and bore each
    azimuth has its own sector."""
    if not isinstance(material, Material):
        raise ParameterError(f"material must be a Material, got {type(material).__name__}")
    s = np.atleast_1d(np.asarray(distances_mm, dtype=np.float64))
    if s.size == 0 or not np.all(np.isfinite(s) & (s >= 0)):
        raise ParameterError(f"distances must be finite and >= 0 mm, got {distances_mm!r}")
    h = ring_halfwidth(s, material) if halfwidth_mm is None else np.broadcast_to(
        np.asarray(halfwidth_mm, dtype=np.float64), s.shape)
    if not np.all(np.isfinite(h) & (h > 0)):
        raise ParameterError(f"ring half-widths must be finite and > 0 mm, got {halfwidth_mm!r}")
    lo, hi = np.maximum(s - h, 0.0), s + h
    kind = str(shape).lower()
    try:
        inc = float(incidence_deg)
    except (TypeError, ValueError):
        inc = math.nan
    if not 0.0 <= inc < 90.0 or (inc > 0.0 and kind != "plane"):
        raise ParameterError(f"incidence must be in [0, 90) degrees, and oblique only on the plane; got "
                             f"{incidence_deg!r} on a {kind}")
    sin_t = math.sin(math.radians(inc)) / float(material.eta)
    azimuths = [float(a) for a in np.atleast_1d(np.asarray(azimuths_deg, dtype=np.float64))]
    if not azimuths or not all(math.isfinite(a) for a in azimuths):
        raise ParameterError(f"azimuths must be finite angles in degrees, got {azimuths_deg!r}")
    folded = [abs(math.atan2(abs(math.sin(math.radians(a))), abs(math.cos(math.radians(a))))) for a in azimuths]
    _check(kind, radius_mm, s, lo, hi, folded[0], photons, n_batches, sector_deg)
    R = float(radius_mm) if kind != "plane" else 0.0
    sectors = [(max(0.0, f - math.radians(sector_deg)), min(math.pi / 2, f + math.radians(sector_deg)))
               for f in folded]
    like = HOLLOW_OF.get(kind, kind)
    if like == "sphere":
        hi = np.minimum(hi, np.pi * R)   # the ring at the antipode is a cap
    n_az = len(sectors)
    wraps = [(hi * math.cos(sec[0]) > np.pi * R) if like == "cylinder" else np.zeros(s.size, dtype=bool)
             for sec in sectors]
    areas = [ring_area(kind, R, lo, hi, sec) for sec in sectors]
    code = SHAPE_KINDS.index(kind)
    g = float(material.g)
    t0 = time.perf_counter()
    out = {k: np.zeros((n_az, 3, s.size)) for k in ("R", "Re", "S", "Se")}
    tot, tot_e = np.zeros(3), np.zeros(3)
    lost = 0
    done: dict = {}
    for ch in range(3):
        sigma_s = float(material.medium.sigma_s[ch])
        sigma_a = float(material.medium.sigma_a[ch])
        key = (sigma_s, sigma_a)
        if key in done:
            src = done[key]
            for k in out:
                out[k][:, ch] = out[k][:, src]
            tot[ch], tot_e[ch] = tot[src], tot_e[src]
            continue
        done[key] = ch
        sigma_t = sigma_s + sigma_a
        base = np.uint64(stream_base(np.uint64(seed), ch))   # uint64: a Python int would be typed int64
        ring = np.zeros((n_az, n_batches, s.size))
        ring1 = np.zeros((n_az, n_batches, s.size))
        total = np.zeros(n_batches)
        for start in range(0, photons, CHUNK):
            n = min(CHUNK, photons - start)
            ex, ey, ez, ew = (np.empty(n) for _ in range(4))
            order = np.empty(n, dtype=np.int64)
            walk_shape(code, R, sigma_t, sigma_s / sigma_t, g, float(material.eta), base, start, n,
                       ROULETTE_THRESHOLD, ROULETTE_BOOST, MAX_EVENTS, ex, ey, ez, ew, order, sin_t)
            lost += int(np.count_nonzero(order < 0))
            batch = (np.arange(start, start + n, dtype=np.int64) * n_batches) // photons
            out_ok = ew > 0.0
            d, ang = exit_coordinates(kind, R, ex[out_ok], ey[out_ok], ez[out_ok])
            w, b, o = ew[out_ok], batch[out_ok], order[out_ok]
            total += np.bincount(b, weights=w, minlength=n_batches)
            for q, sec in enumerate(sectors if like == "cylinder" else sectors[:1]):
                dq, wq, bq, oq = d, w, b, o
                if like == "cylinder":
                    keep = (ang >= sec[0]) & (ang <= sec[1])
                    dq, wq, bq, oq = d[keep], w[keep], b[keep], o[keep]
                for j in range(s.size):
                    sel = (dq >= lo[j]) & (dq < hi[j])
                    ring[q, :, j] += np.bincount(bq[sel], weights=wq[sel], minlength=n_batches)
                    one = sel & (oq == 1)
                    ring1[q, :, j] += np.bincount(bq[one], weights=wq[one], minlength=n_batches)
            if progress is not None:
                progress(n)
        if like != "cylinder":   # no sectors: every azimuth has the one full ring
            ring[1:], ring1[1:] = ring[0], ring1[0]
        # batch sums of the estimate per unit entering power (every photon enters with weight 1)
        for q in range(n_az):
            out["R"][q, ch], out["Re"][q, ch] = batch_stats(ring[q] / areas[q] / photons)
            out["S"][q, ch], out["Se"][q, ch] = batch_stats(ring1[q] / areas[q] / photons)
        t_sum, t_err = batch_stats((total / photons)[:, None])
        tot[ch], tot_e[ch] = t_sum[0], t_err[0]
    for q in range(n_az):   # a cylinder's sector that reaches half the girth around it: the unrolled area fails
        for k in out:
            out[k][q][:, wraps[q]] = np.nan
    seconds = time.perf_counter() - t0
    return [ShapeProfile(kind, R if kind != "plane" else None, s, lo, hi, azimuths[q], out["R"][q], out["Re"][q],
                         out["S"][q], out["Se"][q], tot, tot_e, lost, int(photons), seconds) for q in range(n_az)]
