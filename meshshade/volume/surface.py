"""The surface the volume transport samples (docs/physics.md §15.5): the mesh, with its long edges split until
none is longer than the lattice resolves.

Where light enters and where exitance is read are points of the surface, not only vertices of the input: a coarse
asset (edges of several millimetres on skin) is sampled on its facets, split where they are long (edges halved in
rounds until every edge is within ``spacing``; a triangle with one, two or three halved edges becomes two, three
or four; the split is conforming and nothing is moved: the same polyhedron). New vertices take the facets' own
normals (so light enters each flat facet at the facet's angle, as it does in the Monte Carlo).

The exitance is one field, P1 on the split surface, and every output reads its point values: the input's vertices
are the split surface's first vertices, so a vertex takes the solution there (:meth:`SamplingSurface.to_vertices`),
and a texel or a pixel takes it at its own point (:meth:`SamplingSurface.locate`). The Monte Carlo tallies
something else, the average over a vertex's patch weighted by its hat function (the barycentric weight of each exit
point); the same average of the field, for comparing with it, is eq. (104) (:meth:`SamplingSurface.patch_average`):

    M_v = int w_v M dA / int w_v dA,   w_v = the P1 basis function of v on the input mesh,                (104)

integrated exactly over the split triangles with M linear on each.
"""
from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from meshshade.geometry.mesh import Mesh, MeshReport

__all__ = ["SamplingSurface", "split_long_edges", "MAX_SAMPLES"]

#: the split surface holds at most this many vertices (the splitting stops there, with a note in the stats)
MAX_SAMPLES = 3_000_000
#: rounds of halving (a 26 mm edge at 0.4 mm needs 7)
MAX_ROUNDS = 12


def split_long_edges(vertices, faces, spacing: float, *, max_vertices: int = MAX_SAMPLES):
    """(V (n', 3), F (m', 3), origin (m',), bary (m', 3, 3), complete): the mesh with every edge longer than
    ``spacing`` halved, round after round; the first vertices are the input's, in order. ``origin`` is each new
    face's face of the input and ``bary`` its corners' barycentric coordinates there (corner, input corner).
    ``complete`` is False if ``max_vertices`` stopped the splitting."""
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    origin = np.arange(F.shape[0])
    bary = np.broadcast_to(np.eye(3), (F.shape[0], 3, 3)).copy()
    complete = True
    for _ in range(MAX_ROUNDS):
        long_ = np.empty(3 * F.shape[0], dtype=bool)                   # edge k of face f at k nf + f: opposite k
        if not _long_edges(V, F, float(spacing), long_):
            break
        which = np.flatnonzero(long_)
        k, f = which // F.shape[0], which % F.shape[0]
        a, b = F[f, (k + 1) % 3], F[f, (k + 2) % 3]
        key = np.minimum(a, b) * np.int64(V.shape[0]) + np.maximum(a, b)
        ukeys, inv = np.unique(key, return_inverse=True)
        if V.shape[0] + ukeys.size > max_vertices:
            complete = False
            break
        ul, uh = ukeys // V.shape[0], ukeys % V.shape[0]
        mid_id = V.shape[0] + np.arange(ukeys.size)
        V = np.concatenate([V, 0.5 * (V[ul] + V[uh])])
        nf = F.shape[0]
        split = np.full(3 * nf, -1, dtype=np.int64)
        split[long_] = mid_id[inv]
        split = split.reshape(3, nf).T                                           # (f, k): midpoint opposite k
        F, origin, bary = _subdivide(F, origin, bary, split)
    return V, F, origin, bary, complete


@numba.njit(cache=True, nogil=True)
def _long_edges(V, F, spacing, out):
    """out[k nf + f] = whether edge k of face f (opposite corner k) is longer than ``spacing``; whether any is."""
    nf = F.shape[0]
    any_long = False
    s2 = spacing * spacing
    for k in range(3):
        for f in range(nf):
            a, b = F[f, (k + 1) % 3], F[f, (k + 2) % 3]
            dx, dy, dz = V[a, 0] - V[b, 0], V[a, 1] - V[b, 1], V[a, 2] - V[b, 2]
            long_ = dx * dx + dy * dy + dz * dz > s2
            out[k * nf + f] = long_
            any_long |= long_
    return any_long


def _subdivide(F, origin, bary, split):
    """Each face split by its halved edges (``split`` (f, 3): the midpoint of the edge opposite corner k, or -1)."""
    nsplit = (split >= 0).sum(axis=1)
    out_f, out_o, out_b = [F[nsplit == 0]], [origin[nsplit == 0]], [bary[nsplit == 0]]
    for count in (1, 2, 3):
        sel = np.flatnonzero(nsplit == count)
        if sel.size == 0:
            continue
        f, s, o, b = F[sel], split[sel], origin[sel], bary[sel]
        # rotate so that the halved edges come first in a fixed order: corner 0 opposite the first halved edge
        if count == 1:
            k = np.argmax(s >= 0, axis=1)
        elif count == 2:
            k = np.argmax(s < 0, axis=1)                  # corner 0 opposite the edge that is not halved
        else:
            k = np.zeros(sel.size, dtype=np.int64)
        idx = (k[:, None] + np.arange(3)[None, :]) % 3
        f = np.take_along_axis(f, idx, axis=1)
        s = np.take_along_axis(s, idx, axis=1)
        b = np.take_along_axis(b, idx[:, :, None], axis=1)
        mb = 0.5 * (b[:, [1, 2, 0]] + b[:, [2, 0, 1]])    # barycentrics of the midpoint opposite each corner
        a0, a1, a2 = f[:, 0], f[:, 1], f[:, 2]
        m0, m1, m2 = s[:, 0], s[:, 1], s[:, 2]
        B0, B1, B2 = b[:, 0], b[:, 1], b[:, 2]
        M0, M1, M2 = mb[:, 0], mb[:, 1], mb[:, 2]
        if count == 1:                                     # m0 on edge a1-a2
            tris = [((a0, a1, m0), (B0, B1, M0)), ((a0, m0, a2), (B0, M0, B2))]
        elif count == 2:                                   # m1 on a2-a0, m2 on a0-a1; edge a1-a2 whole
            tris = [((a0, m2, m1), (B0, M2, M1)), ((m2, a1, a2), (M2, B1, B2)), ((m2, a2, m1), (M2, B2, M1))]
        else:
            tris = [((a0, m2, m1), (B0, M2, M1)), ((m2, a1, m0), (M2, B1, M0)), ((m1, m0, a2), (M1, M0, B2)),
                    ((m0, m1, m2), (M0, M1, M2))]
        for corners, bs in tris:
            out_f.append(np.stack(corners, axis=1))
            out_o.append(o)
            out_b.append(np.stack(bs, axis=1))
    return np.concatenate(out_f), np.concatenate(out_o), np.concatenate(out_b)


class SamplingSurface:
    """``mesh`` sampled at ``spacing`` mm (module docstring): ``samples`` (a :class:`Mesh`: the input itself when
    no edge is longer than ``spacing``; the input's vertices first, in order), :meth:`to_vertices` the field at the
    input's vertices, :meth:`locate` at any point, :meth:`patch_average` eq. (104); ``complete``: False if
    :data:`MAX_SAMPLES` stopped the splitting."""

    def __init__(self, mesh, spacing: float):
        self.source = mesh
        self.spacing = float(spacing)
        V, F, origin, bary, self.complete = split_long_edges(mesh.vertices, mesh.faces, self.spacing)
        self._origin, self._bary = origin, bary
        self._W = None                                                    # eq. (104)'s weights, made when asked
        if F.shape[0] == mesh.n_faces:
            self.samples = mesh
            return
        report = MeshReport(n_vertices=int(V.shape[0]), n_faces=int(F.shape[0]), faces=F)
        self.samples = Mesh(V, F, mm_per_unit=mesh.mm_per_unit, source=mesh.source, defects=report)

    @property
    def split(self) -> bool:
        return self.samples is not self.source

    def to_vertices(self, values):
        """(n_vertices, k): the field of ``values`` (n_samples, k), P1 on the samples, at the input's vertices: the
        first rows (the input's vertices are the samples' first vertices), the same point values a texel or a pixel
        reads there through :meth:`locate`."""
        return np.asarray(values)[:self.source.n_vertices]

    def patch_average(self, values):
        """(n_vertices, k) eq. (104) of ``values`` (n_samples, k), P1 on the samples: the hat-weighted average over
        each input vertex's patch, what the Monte Carlo tallies at a vertex (also where nothing is split: then the
        samples are the input's triangles, and the average of a P1 field is not its vertex value)."""
        if self._W is None:
            self._W = _hat_weights(self.source, self.samples, self._origin, self._bary)
        return self._W @ np.asarray(values)

    def locate(self, face, bary):
        """(sub_face (k,), lam (k, 3)): the face of the sampling surface holding each point given by its input
        ``face`` (k,) and barycentrics ``bary`` (k, 3) there, and the point's barycentrics in it (the split is on
        the input's facets: every point of an input face lies in one of its split faces)."""
        face = np.asarray(face, dtype=np.int64)
        bary = np.asarray(bary, dtype=np.float64)
        if not self.split or face.size == 0:
            return face, bary
        inv = getattr(self, "_inv", None)
        if inv is None:
            inv = self._inv = np.linalg.inv(self._bary)                 # lam = bary @ inv(B_q)
            src = self.source
            cent = np.einsum("qkm,qmd->qd", self._bary / 3.0, src.vertices[src.faces[self._origin]])
            self._tree = cKDTree(cent)
            self._by_origin = np.argsort(self._origin, kind="stable")
            self._first = np.searchsorted(self._origin[self._by_origin], np.arange(src.n_faces + 1))
        src = self.source
        pts = np.einsum("km,kmd->kd", bary, src.vertices[src.faces[face]])
        sub = np.full(face.size, -1, dtype=np.int64)
        best = np.full(face.size, -np.inf)
        k = int(min(8, self._tree.n))
        _, cand = self._tree.query(pts, k=k)
        cand = cand.reshape(face.size, k)
        for j in range(k):                                                # nearest split faces of the same face
            q = cand[:, j]
            lam_min = np.einsum("km,kmc->kc", bary, inv[q]).min(axis=1)
            ok = (self._origin[q] == face) & (lam_min > best)
            sub[ok], best[ok] = q[ok], lam_min[ok]
        rest = np.flatnonzero(best < -1e-9)                               # not found among them: all of its face
        if rest.size:
            f = face[rest]
            cnt = self._first[f + 1] - self._first[f]
            owner = np.repeat(np.arange(rest.size), cnt)
            offs = np.arange(owner.size) - np.repeat(np.cumsum(cnt) - cnt, cnt)
            q = self._by_origin[np.repeat(self._first[f], cnt) + offs]
            lam_min = np.einsum("km,kmc->kc", bary[rest][owner], inv[q]).min(axis=1)
            order = np.lexsort((-lam_min, owner))
            firsts = order[np.searchsorted(owner[order], np.arange(rest.size))]
            sub[rest] = q[firsts]
        lam = np.einsum("km,kmc->kc", bary, inv[sub])
        lam = np.clip(lam, 0.0, None)
        return sub, lam / lam.sum(axis=1, keepdims=True)


def _hat_weights(mesh, split, origin, bary):
    """CSR (n_v, n_s): eq. (104)'s weights, each row normalised. The integral of w_v times the split surface's P1
    function over a split face of area a is a/12 (sum_k w_v(k) M_k + sum_k w_v(k) sum_k M_k), w_v(k) the corner
    k's barycentric of v in the input face."""
    area = split.face_areas
    s = bary.sum(axis=1)                                                   # (Q, m): sum over corners
    w = area[:, None, None] / 12.0 * (bary + s[:, None, :])                # (Q, corner k, input corner m)
    rows = np.broadcast_to(mesh.faces[origin][:, None, :], w.shape).ravel()
    cols = np.broadcast_to(split.faces[:, :, None], w.shape).ravel()
    W = sp.csr_matrix((w.ravel(), (rows, cols)), shape=(mesh.n_vertices, split.n_vertices))
    W.sum_duplicates()
    tot = np.asarray(W.sum(axis=1)).ravel()
    inv = np.divide(1.0, tot, out=np.zeros_like(tot), where=tot > 0)
    return sp.diags(inv) @ W
