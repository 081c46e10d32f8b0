"""Light that crosses the object without a collision: the entering light that reaches the far side of a thin part
before it scatters (docs/physics.md §15.6, eqs. (130)-(131)).

The lattice's sources (:mod:`meshshade.volume.long_range`) are where the entering light first scatters, density
alpha' sigma_t' P exp(-sigma_t' t) along the refracted ray; what has not scattered by the time the ray meets the
surface again, P exp(-sigma_t' L), leaves there (or is reflected back in, Fresnel). In a half-space it never
meets the surface again; across a part a few mean free paths thick (an ear, a finger, a thin wall) in a medium
that absorbs much of what it scatters (ketchup's green and blue), it is most of the light on the far side.

:func:`face_entries` splits each vertex's entry over the faces around it, as the Monte Carlo's photons enter
(refracted by each face's own normal); :func:`uncollided_exitance` follows each entry's refracted ray with Embree:
at each face it meets, the unscattered power (eq. (130)) leaves with the Fresnel transmittance from inside and the
rest is reflected and followed on, up to ``MAX_EVENTS`` faces or until under ``FLOOR`` of its start; what leaves is
put on the hit face's corners by the exit point's barycentrics over the corners' areas (eq. (131)), as the Monte
Carlo tallies its exits. Faces with the medium on both sides (parts overlapping, a fin) are crossed without an
event and a ray that has left the medium through a hole is lost, both decided by the winding number on either side
of the face (as the Monte Carlo's walk surface decides them, eq. (127)) where the surface is not one closed part.
Extinction is the similar medium's sigma_t' (the diffusion's and the sources', so that sources and this term share
the entering power exactly); in a medium varying over the object, its optical depth along each segment by a
midpoint rule. No I/O.
"""
from __future__ import annotations

import numpy as np

from meshshade.kernels.fresnel import fresnel_reflectance, fresnel_transmittance_entry, refract_in

__all__ = ["uncollided_exitance", "face_entries", "FLOOR", "PREFILTER_MARGIN", "MAX_EVENTS", "DEPTH_POINTS"]

#: a ray is followed until its largest channel's power falls under this share of its entering power (the rest is
#: booked as absorbed; the Monte Carlo's roulette starts at the same 1e-4 of a photon's weight)
FLOOR = 1e-4
#: an entry is split over its faces only where its own ray keeps more than this share of FLOOR (by the least
#: extinction over the channels) at the face it meets first
PREFILTER_MARGIN = 1e-2
#: faces a ray meets at most (each either an exit with a Fresnel reflection back in, or crossed); what is left
#: after the last is booked as lost
MAX_EVENTS = 16
#: points of the midpoint rule of a varying medium's optical depth along one segment
DEPTH_POINTS = 16


def uncollided_exitance(scene, vertex_areas, positions, normals, directions, power, eta, *, sigma_t_prime=None,
                        optical_depth=None, sides=None, floor: float = FLOOR, max_events: int = MAX_EVENTS):
    """(M (n, 3) W/mm^2 at the vertices of ``scene``'s surface, stats): the light entering at ``positions``
    (k, 3) mm with outward ``normals`` (k, 3), refracted unit ``directions`` (k, 3) and ``power`` (k,) W, that
    leaves the surface unscattered (module docstring).

    scene : the surface's ray scene (:func:`meshshade.raycast.make_scene`; its faces index ``vertex_areas``)
    vertex_areas : (n,) mm^2, each vertex's third of its faces' areas
    eta : the medium's index (1 outside)
    sigma_t_prime : (3,) 1/mm, the medium's reduced extinction, or None with ``optical_depth(origins, directions,
        lengths) -> (m, 3)`` (a varying medium) with its lower bound ``optical_depth.sigma_min`` (3,) 1/mm
    sides : None where every face is the medium's boundary (one closed part), else ``sides(points) -> (p,) bool``,
        whether each point is in the medium (the winding number above 1/2)
    Returns M and stats: ``left`` (3,) W leaving, ``lost`` (3,) W through holes or after ``max_events``,
    ``rays`` cast.
    """
    V, F = scene.vertices, scene.faces
    positions = np.asarray(positions, dtype=np.float64)
    directions = np.asarray(directions, dtype=np.float64)
    power = np.asarray(power, dtype=np.float64)
    n_v = V.shape[0]
    deposit = np.zeros((n_v, 3))
    stats = {"left": np.zeros(3), "lost": np.zeros(3), "rays": 0}
    if sigma_t_prime is not None:
        sig_min = np.asarray(sigma_t_prime, dtype=np.float64)
    else:
        sig_min = np.asarray(optical_depth.sigma_min, dtype=np.float64)
    keep = power > 0.0
    o = scene.offset_origins(positions[keep], normals[keep], sign=-1.0)
    d = directions[keep]
    w = np.repeat(power[keep, None], 3, axis=1)                     # (m, 3) W still unscattered
    cut = floor * power[keep]                                       # per ray: below this it is dropped
    half_diag = 0.5 * scene.scale
    for _ in range(max_events):
        if o.shape[0] == 0:
            break
        hits = scene.first_hit(o, d)
        stats["rays"] += int(o.shape[0])
        hit = hits.hit
        stats["lost"] += w[~hit].sum(axis=0)                       # out through an opening of the surface
        L = hits.t
        # a lower bound of the optical depth first: most rays of a thick part end here, before any quadrature
        alive = hit & (np.max(w * np.exp(-np.outer(np.where(hit, L, 0.0), sig_min)), axis=1) >= cut)
        o, d, w, cut, L = o[alive], d[alive], w[alive], cut[alive], L[alive]
        face, bary, pts = hits.face[alive], hits.bary[alive], hits.points[alive]
        if sigma_t_prime is not None:
            tau = np.outer(L, sig_min)
        else:
            tau = np.asarray(optical_depth(o, d, L), dtype=np.float64)
        w = w * np.exp(-tau)                                         # eq. (130)
        alive = np.max(w, axis=1) >= cut
        d, w, cut, face, bary, pts = d[alive], w[alive], cut[alive], face[alive], bary[alive], pts[alive]
        n = np.cross(V[F[face, 1]] - V[F[face, 0]], V[F[face, 2]] - V[F[face, 0]])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        cos = np.einsum("ij,ij->i", d, n)
        if sides is None:
            # one closed part, wound outward: a face met from its outside means the ray was not in the medium
            # (it left it where an entry's vertex normal points out of a fold); such light is the near field's
            before, cross = cos > 0.0, np.zeros(d.shape[0], dtype=bool)
        else:                                                         # the medium on which side (eq. (127))
            edge = np.max(np.linalg.norm(V[F[face]] - V[F[face][:, [1, 2, 0]]], axis=2), axis=1)
            delta = np.maximum(1e-4 * edge, 1e-5 * half_diag)[:, None]
            before = sides(pts - delta * d)
            cross = before & sides(pts + delta * d)
        n *= np.where(cos < 0.0, -1.0, 1.0)[:, None]                   # the face's normal on the ray's way out
        cos = np.abs(cos)
        stats["lost"] += w[~before].sum(axis=0)                     # it had left through a hole or a fold
        if not before.all():
            d, w, cut, face, bary, pts, n, cos, cross = (
                a[before] for a in (d, w, cut, face, bary, pts, n, cos, cross))
        R = fresnel_reflectance(cos, float(eta), 1.0)                # from inside (1 under total reflection)
        R = np.where(cross, 0.0, R)
        out = np.where(cross, 0.0, 1.0 - R)[:, None] * w             # leaves here, eq. (131)
        ex = ~cross
        for c in range(3):                                            # on the face's corners (eq. (131))
            deposit[:, c] += np.bincount(F[face[ex]].ravel(), weights=(bary[ex] * out[ex, c, None]).ravel(),
                                         minlength=n_v)
        stats["left"] += out.sum(axis=0)
        # on: crossed faces unchanged, exits reflected back in with the Fresnel share
        w = np.where(cross[:, None], w, R[:, None] * w)
        d_new = np.where(cross[:, None], d, d - 2.0 * cos[:, None] * n)
        alive = np.max(w, axis=1) >= cut
        # a crossed face is left along the ray, a reflection starts just inside the face
        step = np.where(cross[:, None], d, -n)[alive]
        o = scene.offset_origins(pts[alive], step, sign=1.0)
        d, w, cut = d_new[alive], w[alive], cut[alive]
    stats["lost"] += w.sum(axis=0)                                   # past the last event
    areas = np.asarray(vertex_areas, dtype=np.float64)
    M = np.where(areas[:, None] > 0.0, deposit / np.where(areas > 0.0, areas, 1.0)[:, None], 0.0)
    return M, stats


def face_entries(vertices, faces, vertex, positions, directions, normals, power, eta):
    """(positions (q, 3), normals (q, 3), refracted directions (q, 3), power (q,)): the entries at vertices split
    over their faces, as the Monte Carlo's photons enter (eq. (68)). Entry ``i`` at ``vertex[i]`` becomes one entry
    per face of that vertex, at the centroid of the vertex's third of the face (2/3 the vertex, 1/6 each other
    corner), refracted by the face's geometric normal (turned to the vertex normal's side), with the share of
    ``power[i]`` of the face's A_f/3 cos_f F_t(cos_f) (cos_f of the light's ``directions[i]`` on the face; none
    where the face turns away). A point entry (``vertex[i]`` = -1, a beam's hit) and an entry none of whose faces
    faces the light are kept as they are (at ``positions[i]``, refracted by ``normals[i]``). ``vertices`` (n, 3),
    ``faces`` (m, 3) the surface's; the rest per entry (k,)."""
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    vertex = np.asarray(vertex, dtype=np.int64)
    at_v = np.flatnonzero(vertex >= 0)
    inc_v, inc_f = F.ravel(), np.repeat(np.arange(F.shape[0]), 3)          # (vertex, face) incidences
    order = np.argsort(inc_v, kind="stable")
    inc_f = inc_f[order]
    first = np.searchsorted(inc_v[order], np.arange(V.shape[0] + 1))
    v = vertex[at_v]
    count = first[v + 1] - first[v]
    owner = np.repeat(np.arange(at_v.size), count)                        # each (entry, face) pair's entry
    offs = np.arange(owner.size) - np.repeat(np.cumsum(count) - count, count)
    f = inc_f[np.repeat(first[v], count) + offs]
    tri = V[F[f]]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(n, axis=1)
    n = n / np.where(area > 0.0, 2.0 * area, 1.0)[:, None]
    e = at_v[owner]
    n *= np.where(np.einsum("ij,ij->i", n, normals[e]) < 0.0, -1.0, 1.0)[:, None]
    d = directions[e]
    cos = np.clip(-np.einsum("ij,ij->i", d, n), 0.0, 1.0)
    weight = area / 3.0 * cos * fresnel_transmittance_entry(cos, eta)
    total = np.bincount(owner, weights=weight, minlength=at_v.size)
    keep = (total[owner] > 0.0) & (weight > 0.0)
    share = weight[keep] / total[owner][keep] * power[e][keep]
    split = np.zeros(len(vertex), dtype=bool)
    split[e[keep]] = True
    whole = np.flatnonzero(~split)
    return (np.concatenate([V[v[owner]][keep] / 2.0 + tri[keep].sum(axis=1) / 6.0, positions[whole]]),
            np.concatenate([n[keep], normals[whole]]),
            np.concatenate([refract_in(d[keep], n[keep], eta), refract_in(directions[whole], normals[whole], eta)]),
            np.concatenate([share, power[whole]]))
