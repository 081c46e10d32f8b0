"""The kernel R(x_o; x_i) of one model evaluated for arrays of (entry sample, exit vertex) pairs.

The kernel is expanded at the entry point x_i (docs/physics.md §1.3): rho is the geodesic distance from x_i to x_o,
phi the direction of x_o in x_i's tangent plane from x_i's first principal direction, and k1, k2 are x_i's
principal curvatures (:class:`SourceFrames`). :class:`PairKernel` evaluates the kernel of each source
(:class:`~meshshade.surface.models.Kernel`, from the model or the auto plan) per channel for arrays of pairs,
through the one compiled evaluation :func:`~meshshade.surface.kernel_evaluation.kernel_value`; the patch average
of a vertex sample's kernel is :mod:`meshshade.surface.patch_average`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshshade.errors import ParameterError
from meshshade.kernels.curvature import VALIDITY_TOL
from meshshade.kernels.fitted_curvature import chord_curvature, normal_curvatures
from meshshade.materials import Material
from meshshade.surface.kernel_evaluation import (SPHERE_THETA_POINTS, KernelParams, SphereTables, curved_values,
                                                   kernel_params, kernel_values)
from meshshade.surface.models import MODEL_KERNEL, MODELS, Kernel


@dataclass(frozen=True)
class SourceFrames:
    """Entry-sample geometry the kernel needs, (k,) or (k, 3) float64: curvatures in 1/mm, unit frames."""

    k1: np.ndarray
    k2: np.ndarray
    d1: np.ndarray
    d2: np.ndarray
    normals: np.ndarray


def source_frames(samples, curv, faces) -> SourceFrames:
    """Principal curvatures and frames at entry samples: vertex values for vertex samples, barycentric
    interpolation (directions sign-aligned, re-orthogonalised to the sample's normal) inside a triangle.

    samples : EntrySamples (k samples); curv : per-vertex ``k1``, ``k2`` (n,) 1/mm and ``d1`` (n, 3);
    faces : (m, 3) int. Returns (k,) / (k, 3) float64 frames with ``d2 = normal x d1``.
    """
    k = len(samples)
    k1, k2 = np.empty(k), np.empty(k)
    d1 = np.empty((k, 3))
    at_v = samples.vertex >= 0
    iv = samples.vertex[at_v]
    k1[at_v], k2[at_v], d1[at_v] = curv.k1[iv], curv.k2[iv], curv.d1[iv]
    tri = ~at_v
    if np.any(tri):
        F = faces[samples.face[tri]]
        b = samples.bary[tri]
        k1[tri] = np.einsum("ij,ij->i", b, curv.k1[F])
        k2[tri] = np.einsum("ij,ij->i", b, curv.k2[F])
        D = curv.d1[F]  # (t, 3, 3): principal directions are defined up to sign: align to corner 0
        sign = np.sign(np.einsum("ijk,ik->ij", D, D[:, 0]))
        sign[sign == 0] = 1.0
        d1[tri] = np.einsum("ij,ijk->ik", b * sign, D)
    # an unreferenced vertex (no face: zero area, zero normal, no power) gets the frame of +z: any will do
    length = np.linalg.norm(samples.normals, axis=1, keepdims=True)
    n = np.where(length > 0, samples.normals / np.where(length > 0, length, 1.0), [[0.0, 0.0, 1.0]])
    d1 = d1 - np.einsum("ij,ij->i", d1, n)[:, None] * n
    norm = np.linalg.norm(d1, axis=1)
    bad = norm < 1e-12
    if np.any(bad):  # umbilic or failed frame: any tangent direction will do (k1 = k2 there)
        alt = np.where(np.abs(n[bad, 0:1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
        d1[bad] = np.cross(n[bad], alt)
        norm[bad] = np.linalg.norm(d1[bad], axis=1)
    d1 /= norm[:, None]
    d2 = np.cross(n, d1)
    return SourceFrames(k1, k2, d1, d2, n)


class PairKernel:
    """Evaluates R [mm^-2] of one model and material for arrays of (source, exit) pairs.

    Each source takes one :class:`~meshshade.surface.models.Kernel`: the model's, or for ``model="auto"`` the
    one its plan gives (``plan``, meshshade.surface.auto.AutoPlan). Every pair is evaluated by
    :func:`~meshshade.surface.kernel_evaluation.kernel_values` with the :class:`KernelParams` ``params`` (built
    here, reaching ``reach_mm`` or the longest pair seen, when not given). Exact-sphere sources read the series
    from :class:`SphereTables` (``sphere``, built here when not given), except that a radius bin with at most
    ``sphere_series_pairs`` pairs in one call (a beam) takes the series at each pair exactly. Channels with equal
    parameters are computed once (``channels``).
    """

    def __init__(self, model: str, material: Material, frames: SourceFrames, *, rtol: float = 1e-10, plan=None,
                 near=None, params: KernelParams | None = None, sphere: SphereTables | None = None,
                 reach_mm=None, sphere_series_pairs: int = SPHERE_THETA_POINTS):
        if model not in MODELS or model == "volume":
            raise ParameterError(f"unknown surface model {model!r}; choose one of "
                                 f"{', '.join(m for m in MODELS if m != 'volume')}")
        #: the near-field factors (surface.source_factors.NearFieldFactors) the gather multiplies pairs by, or None
        #: for the kernels' own point source at z_r; with them, ``source_scale`` (k, 3): each source's incidence
        #: scale per channel (NearFieldFactors.incidence_scale), or None
        self.near_factors = near
        self.source_scale = None
        #: with the near-field factors, each source's sideways drift (sin theta_t (k,), its azimuth psi (k,) in the
        #: source frame; surface.source_factors.drift_angles), or None: the gather multiplies pairs by
        #: NearFieldFactors.drift_factor (docs/physics.md eq. (88))
        self.source_drift = None
        if model == "auto" and plan is None:
            raise ValueError("model 'auto' needs the per-sample plan (meshshade.surface.auto.plan_sources)")
        self.model, self.material, self.frames, self.plan = model, material, frames, plan
        #: (k,) int8: each source's kernel
        self.kind = (np.asarray(plan.kernel, dtype=np.int8) if model == "auto"
                     else np.full(len(frames.k1), MODEL_KERNEL[model], dtype=np.int8))
        self.channels: list[tuple[int, list[int]]] = []  # (representative channel, channels it stands for)
        seen: dict = {}
        for c in range(3):
            key = (material.albedo_prime[c], material.sigma_t_prime[c])
            if key in seen:
                self.channels[seen[key]][1].append(c)
            else:
                seen[key] = len(self.channels)
                self.channels.append((c, [c]))
        self.stats: dict = {}
        self.sphere = sphere if sphere is not None else SphereTables(material, rtol)
        self.sphere_series_pairs = int(sphere_series_pairs)
        self.params = params
        self._reach = (np.full(3, np.inf) if params is not None
                       else None if reach_mm is None else np.broadcast_to(np.asarray(reach_mm, float), (3,)).copy())
        #: (source positions (k, 3) mm, receiver positions (n, 3) mm, receiver unit normals (n, 3), receiver
        #: principal curvatures k1, k2 (n,) 1/mm and first principal directions (n, 3)), or None: with them the
        #: fitted model measures each pair's curvatures between its two points (:meth:`_pair_curvatures`) when
        #: :meth:`evaluate` is given the receivers
        self.pair_points = None
        self._bin = np.full(len(frames.k1), -1, dtype=np.int64)   # exact-sphere radius bin per source
        self._row = np.full(len(frames.k1), -1, dtype=np.int64)   # ... and its table row, once built
        sph = self.kind == Kernel.EXACT_SPHERE
        if np.any(sph):
            self._bin[sph] = SphereTables.bin_keys(0.5 * (frames.k1[sph] + frames.k2[sph]))
            if model == "exact-sphere":
                self.stats["exact_sphere_fallback_dipole"] = int((self._bin < 0).sum())
                self.stats["exact_sphere_radius_bins"] = int(np.unique(self._bin[self._bin >= 0]).size)
        self.rtol = rtol

    def evaluate(self, c: int, src, s, chord, phi, vtx=None) -> np.ndarray:
        """R [mm^-2] of channel ``c`` for pairs with source indices ``src`` (into the frames), geodesic distance
        ``s`` [mm], chord [mm] and azimuth ``phi`` [rad]; all (p,), returns (p,) float64. ``vtx`` (p,): the
        receivers' indices into ``pair_points``, or None."""
        src = np.asarray(src, dtype=np.int64)
        s, chord, phi = (np.ascontiguousarray(x, dtype=np.float64) for x in (s, chord, phi))
        out = np.empty(s.shape)
        if not s.size:
            return out
        kind = np.ascontiguousarray(self.kind[src])
        kinds = np.flatnonzero(np.bincount(kind, minlength=len(Kernel)))
        row, series = self._sphere_rows(src, kind) if Kernel.EXACT_SPHERE in kinds else (None, ())
        params = self._params_for(s)   # after the sphere rows: their tables may have grown
        for k in kinds:   # one kind per call: each compiled loop holds one kernel
            m = slice(None) if kinds.size == 1 else np.flatnonzero(kind == k)
            part = out if kinds.size == 1 else np.empty(m.size)
            if k == Kernel.CURVED:   # curvatures by Euler's formula and the first-order range, in one pass
                f = self.frames
                n_out = curved_values(c, s[m], phi[m], np.ascontiguousarray(f.k1[src[m]]),
                                      np.ascontiguousarray(f.k2[src[m]]), params, VALIDITY_TOL, part)
                self.stats["curved_pairs_out_of_first_order_range"] = (
                    self.stats.get("curved_pairs_out_of_first_order_range", 0) + int(n_out))
            else:
                ka, kc, t2 = self._pair_geometry(k, src[m], phi[m], None if vtx is None else np.asarray(vtx)[m])
                kernel_values(int(k), c, chord[m], s[m], ka, kc, t2,
                              row[m] if row is not None else np.full(part.size, -1, np.int64), params, part)
            if kinds.size > 1:
                out[m] = part
        if len(series):   # radius bins with few pairs: the series at each pair
            bins = self._bin[src[series]]
            for b in np.unique(bins):
                sel = series[bins == b]
                R0 = SphereTables.bin_radius(b)
                out[sel] = self.sphere.series(c, R0, np.clip(s[sel] / R0, 0.0, np.pi))
        return out

    def _pair_geometry(self, kind, src, phi, vtx):
        """(k_along, k_across, tau^2) (p,) 1/mm of the pairs of one non-curved kernel: for FITTED the source's
        normal curvatures (Euler's formula), with the receivers known measured between the points
        (:meth:`_pair_curvatures`); zeros for the dipoles and the exact sphere, which read none."""
        if kind != Kernel.FITTED:
            z = np.zeros(src.size)
            return z, z, z
        ka, kc, t2 = normal_curvatures(phi, self.frames.k1[src], self.frames.k2[src])
        if vtx is not None and self.pair_points is not None:
            ka, kc, t2 = self._pair_curvatures(src, vtx, ka, kc, t2)
        return ka, kc, t2

    def _params_for(self, s) -> KernelParams:
        """The kernel parameters, their curvature tables grown when a longer distance than they reach shows up."""
        s_max = float(s.max())
        if self.params is None or self._reach is None or np.any(self._reach < s_max):
            reach = s_max if self._reach is None else np.maximum(self._reach, s_max)
            kinds = {int(k) for k in np.unique(self.kind)}
            self.params = kernel_params(self.material, reach, self.sphere,
                                        curvature=bool(kinds & {Kernel.CURVED, Kernel.FITTED}))
            self._reach = np.broadcast_to(np.asarray(reach, float), (3,)).copy()
        elif self.params.sphere_r0.size < self.sphere.r0.size:
            self.params = self.params._replace(sphere_log=self.sphere.log_table, sphere_r0=self.sphere.r0)
        return self.params

    def _sphere_rows(self, src, kind):
        """(row per pair (p,), indices of the pairs that take the series exactly): table rows of the exact-sphere
        pairs in bins with more than ``sphere_series_pairs`` pairs (their tables built now), -1 elsewhere."""
        row = np.full(src.shape, -1, dtype=np.int64)
        on = np.flatnonzero((kind == Kernel.EXACT_SPHERE) & (self._bin[src] >= 0))
        if not on.size:
            return row, on
        bins, inv, counts = np.unique(self._bin[src[on]], return_inverse=True, return_counts=True)
        few = counts[inv] <= self.sphere_series_pairs
        tab = on[~few]
        if tab.size:
            need = np.unique(src[tab])
            need = need[self._row[need] < 0]
            if need.size:
                self._row[need] = self.sphere.rows_of_keys(self._bin[need])
                if self.params is not None:
                    self.params = self.params._replace(sphere_log=self.sphere.log_table, sphere_r0=self.sphere.r0)
            row[tab] = self._row[src[tab]]
        return row, on[few]

    def _pair_curvatures(self, src, vtx, ka, kc, t2):
        """The fitted model's curvatures of pairs whose receivers are known (docs/physics.md eq. (85)): along the pair
        the normal-section curvature between its two points; across it and the squared twist, the mean of the
        source's and the receiver's (the receiver's normal curvature across the pair's direction in its tangent
        plane). A surface that bends differently away from the entry point is then seen as it is, not as the
        entry point's osculating quadric extrapolated (on spheres, cylinders around their axis and cavities the
        two agree)."""
        xs, xr, nr, rk1, rk2, rd1 = self.pair_points
        ka = chord_curvature(xs[src], self.frames.normals[src], xr[vtx], nr[vtx], ka)
        v = xr[vtx] - xs[src]
        n = nr[vtx]
        tv = v - np.einsum("ij,ij->i", v, n)[:, None] * n
        across = np.cross(n, tv)
        norm = np.linalg.norm(across, axis=1)
        ok = norm > 0.0
        c2 = np.where(ok, np.einsum("ij,ij->i", rd1[vtx], across) / np.where(ok, norm, 1.0), 0.0) ** 2
        kc = np.where(ok, 0.5 * (kc + rk1[vtx] * c2 + rk2[vtx] * (1.0 - c2)), kc)
        t2 = np.where(ok, 0.5 * (t2 + (rk1[vtx] - rk2[vtx]) ** 2 * c2 * (1.0 - c2)), t2)
        return ka, kc, t2
