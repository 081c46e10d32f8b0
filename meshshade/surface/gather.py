"""The gather: M[v, c] = sum_i Phi_i R_c(x_v; x_i) over the (entry sample, vertex) pairs of each sample's neighbourhood.

Each entry sample reaches the vertices within a cutoff radius chosen per channel from the dipole's closed-form
tail (:func:`cutoff_radii`: the reflectance beyond it is below ``cutoff_tol`` of the total). Sources are
processed in chunks so that memory stays bounded (:class:`PairStream` yields the pairs of one chunk at a time,
zone by zone, see zones.py); the gather per chunk is vectorised (``np.bincount``), never a Python loop over
vertices (:func:`gather`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from meshshade.kernels.dipole import dipole_cutoff_radii
from meshshade.materials import Material
from meshshade.progress import kernel_interrupts
from meshshade.surface.sample_groups import group_samples, expand_far_pairs
from meshshade.surface.pair_kernel import PairKernel, SourceFrames
from meshshade.surface.patch_average import PATCH_AVERAGE_RADII, patch_average_factor
from meshshade.surface.zones import NEAR_MARGIN, ZONES, group_geometry

#: pairs evaluated per chunk (memory ~ 100 bytes per pair)
PAIRS_PER_CHUNK = 4_000_000


def cutoff_radii(material: Material, tol: float) -> np.ndarray:
    """(3,) mm: per channel, the radius beyond which the dipole's reflectance is below ``tol`` of its total."""
    return dipole_cutoff_radii(tol, sigma_t_prime=material.sigma_t_prime, albedo_prime=material.albedo_prime,
                               eta=material.eta)


def gather(kernel: PairKernel, n_vertices: int, power, cutoff_mm, pairs_iter, source_radius=None,
           chord_cutoff_mm=None, receiver_radius=None) -> tuple[np.ndarray, dict]:
    """Accumulate M[v, c] = sum_i power_i R_c(pair) over the pair chunks yielded by ``pairs_iter``.

    ``pairs_iter`` yields ``(src, vertex, s, chord, phi)`` arrays (src indexes ``power`` (k,) W and the kernel's
    frames; s and chord in mm, phi in rad). Channel c uses only pairs with s <= cutoff_mm[c] (beyond, its
    reflectance is negligible); ``cutoff_mm`` is (3,), or (k, 3) per source and channel. ``chord_cutoff_mm``
    (k, 3) or None: pairs must also have chord <= it (the near zone of sources whose far field is summed by
    clusters). ``source_radius`` (k,) mm: patch radius of each source (0 for a pencil beam), see
    :func:`~meshshade.surface.patch_average.patch_average_factor`. With the near field of ``kernel.near_factors``
    (surface/source_factors.py) every pair is also multiplied by its near-field factor (and, with
    ``kernel.source_drift``, by the drift factor of eq. (88)), and a point source (a beam)
    is averaged over the receiver's patch, of radius ``receiver_radius`` (n_vertices,) mm: a vertex's exitance
    stands for its patch, and the near field peaks within it. Returns M (n_vertices, 3) W/mm^2 and counts.
    """
    M = np.zeros((n_vertices, 3))
    cutoff_mm = np.asarray(cutoff_mm, dtype=np.float64)
    n_pairs = np.zeros(3, dtype=np.int64)
    for src, vtx, s, chord, phi in pairs_iter:
        for c, same in kernel.channels:
            keep = s <= (cutoff_mm[c] if cutoff_mm.ndim == 1 else cutoff_mm[src, c])
            if chord_cutoff_mm is not None:
                keep &= chord <= chord_cutoff_mm[src, c]
            if not np.any(keep):
                continue
            R = kernel.evaluate(c, src[keep], s[keep], chord[keep], phi[keep], vtx[keep])
            a = None
            if source_radius is not None:
                a = source_radius[src[keep]]
                if kernel.near_factors is not None and receiver_radius is not None:
                    a = np.where(a > 0, a, receiver_radius[vtx[keep]])
                near = np.flatnonzero(s[keep] < PATCH_AVERAGE_RADII * a)
                if near.size:
                    ch = kernel.material.channel(c)
                    R[near] *= patch_average_factor(s[keep][near], a[near], albedo_prime=ch["albedo_prime"],
                                                    eta=ch["eta"], sigma_t_prime=ch["sigma_t_prime"])
            if kernel.near_factors is not None:
                R *= kernel.near_factors.pair_factor(c, s[keep], 0.0 if a is None else a)
                if kernel.source_scale is not None:
                    R *= kernel.source_scale[src[keep], c]
                if kernel.source_drift is not None:
                    sin_t, psi = kernel.source_drift
                    sk = src[keep]
                    R *= kernel.near_factors.drift_factor(c, s[keep], 0.0 if a is None else a, sin_t[sk],
                                                          np.cos(phi[keep] - psi[sk]))
            acc = np.bincount(vtx[keep], weights=power[src[keep]] * R, minlength=n_vertices)
            n_pairs[c] += int(keep.sum())
            for cc in same:
                M[:, cc] += acc
    return M, {"pairs_evaluated": int(n_pairs.sum()), "channels_computed": len(kernel.channels)}


def chunk_size(mesh, src_cut) -> int:
    """Sources per chunk: PAIRS_PER_CHUNK over the expected neighbours per source (the area of its gather disc,
    ``src_cut`` (k, 3) mm, over the mean area per vertex)."""
    per_vertex_area = mesh.total_area / max(mesh.n_vertices, 1)
    expected = max(1.0, np.pi * float(np.mean(src_cut.max(axis=1) ** 2)) / per_vertex_area)
    return int(max(1, min(len(src_cut), PAIRS_PER_CHUNK // expected)))


@dataclass(eq=False)
class PairStream:
    """The chunked pair iteration of the bake: ``(src, vertex, s, chord, phi)`` chunks of ``chunk`` sources.

    mesh : Mesh (mm); samples : EntrySamples (k); frames : SourceFrames of the samples; solvers : geodesic
    neighbourhood solver per method ("exact", "arc"); cut, near : (3,) mm, cutoff and r_near per channel;
    src_cut : (k, 3) mm, geodesic gather radius per source and channel. Time spent finding pairs is charged to
    ``clock``'s "neighbourhoods", time between chunks (the gather) to "gather"; ``bar``
    (:class:`~meshshade.progress.Progress`, or anything with ``update(amount)``, or None) counts sources, also
    within a chunk as the solvers' blocks complete (every few tenths of a second). ``pairs_found`` and
    ``geodesic_pairs`` count the pairs yielded and the geodesic distances a solver computed.
    """

    mesh: object
    samples: object
    frames: SourceFrames
    solvers: dict
    cut: np.ndarray
    near: np.ndarray
    src_cut: np.ndarray
    chunk: int
    clock: Stopwatch
    bar: object = None
    pairs_found: int = 0
    geodesic_pairs: int = 0
    _credited: float = field(default=0.0, init=False, repr=False)  # this chunk's sources counted in ``bar``

    def pairs(self, groups):
        """Pairs of every ``(zone index, source indices)`` group, in order."""
        for z, idx in groups:
            if ZONES[z].outer_method == "exact-shared":
                yield from self._group_pairs(idx)
            else:
                yield from self._zone_pairs(ZONES[z], idx)

    def query(self, method: str, sel, radius, share: float = 0.0, n_sources: int | None = None) -> tuple:
        """Pairs of sources ``sel`` within geodesic ``radius`` (mm, scalar or per source) by solver ``method``;
        the query counts as ``share`` of ``n_sources`` (default ``sel.size``) sources of progress."""
        s, f = self.samples, self.frames
        credit = None
        if self.bar is not None and share > 0:
            worth, start = share * (sel.size if n_sources is None else n_sources), self._credited

            def credit(done, total):
                self._count(start + worth * done / max(total, 1) - self._credited)

        nb = self.solvers[method].query(s.positions[sel], s.face[sel], s.bary[sel], s.vertex[sel], f.normals[sel],
                                        radius, d1=f.d1[sel], d2=f.d2[sel], k1=f.k1[sel], k2=f.k2[sel],
                                        progress=credit)
        return sel[nb.source_index()], nb.vertex.astype(np.int64), nb.distance, nb.chord, nb.phi

    def _count(self, amount: float) -> None:
        if self.bar is not None and amount > 0:
            self._credited += amount
            self.bar.update(amount)

    def _emit(self, p, geodesic_pairs: int, n_sources: int):
        self.pairs_found += p[0].size
        self.geodesic_pairs += geodesic_pairs
        self.clock.lap("neighbourhoods")
        yield p
        self.clock.lap("gather")
        self._count(n_sources - self._credited)  # the chunk's sources, less what its queries counted already
        self._credited = 0.0

    def _zone_pairs(self, zone, idx):
        """One method over each source's whole gather radius, or exact geodesics in the near zone and arc
        geodesics for the rest of the neighbourhood (pairs the near query found are not repeated)."""
        n = np.int64(self.mesh.n_vertices)
        for a in range(0, idx.size, self.chunk):
            sel = idx[a:a + self.chunk]
            if zone.outer_method is None:
                p = self.query(zone.inner_method, sel, self.src_cut[sel].max(axis=1), share=0.9)
                n_geo = p[0].size
            else:
                pi = self.query(zone.inner_method, sel, NEAR_MARGIN * self.near.max(), share=0.45)
                po = self.query(zone.outer_method, sel, self.cut.max(), share=0.45)
                fresh = ~np.isin(po[0] * n + po[1], pi[0] * n + pi[1])
                p = tuple(np.concatenate([x, y[fresh]]) for x, y in zip(pi, po))
                n_geo = pi[0].size + po[0].size
            yield from self._emit(p, n_geo, sel.size)

    def _group_pairs(self, idx):
        """Zone exact_near_shared_far: exact near pairs per sample, far pairs from sample-group centres."""
        samples, mesh, cut = self.samples, self.mesh, self.cut
        size, near_c = group_geometry(mesh, cut)
        order, ptr = group_samples(samples.positions[idx], self.frames.normals[idx], size)
        order = idx[order]
        centre_rows = np.repeat(np.arange(ptr.size - 1), np.diff(ptr))
        centre_of = order[ptr[:-1]][centre_rows]  # the centre sample of each entry of ``order``
        n = np.int64(mesh.n_vertices)
        a_max = float(np.max(np.linalg.norm(samples.positions[order] - samples.positions[centre_of], axis=1)))
        c_chunk = max(1, int(self.chunk * (ptr.size - 1) / max(order.size, 1)))
        for c0 in range(0, ptr.size - 1, c_chunk):
            c1 = min(ptr.size - 1, c0 + c_chunk)
            mem = order[ptr[c0]:ptr[c1]]
            cen = order[ptr[c0:c1]]
            pn = self.query("exact", mem, near_c, share=0.45)
            pc = self.query("exact", cen, cut.max() + a_max, share=0.45, n_sources=mem.size)
            keys = np.sort(pn[0] * n + pn[1])
            with kernel_interrupts():  # numba in this thread: a Ctrl-C is a KeyboardInterrupt, not a SystemError
                pf = expand_far_pairs(pc, (mem, centre_of[ptr[c0]:ptr[c1]]), samples.positions, mesh.vertices,
                                      self.frames, exclude_keys=keys, max_distance=cut.max())
            p = tuple(np.concatenate([x, y]) for x, y in zip(pn, pf))
            yield from self._emit(p, pn[0].size + pc[0].size, mem.size)
