"""The Monte Carlo photon emitter: photons drawn from the lights, Fresnel-split and refracted into the medium.

At entry the unpolarised Fresnel reflectance F(cos) (index 1 outside, ``eta`` inside) is split off
deterministically as specular power and the rest is refracted (Snell) into the medium. A pencil beam enters at its
first hit (float64), a beam of radius R > 0 uniformly over its disc; directional and point lights are sampled over
the faces in proportion to the incident power at the face centroids (point lights then carry an importance
weight), and shadowed photons carry no power. Environment and area lights pick a face in proportion to the bake's
estimate of what enters it, then a direction as the bake's quadrature does (:mod:`meshshade.light.sky_loops`).
Which lights reach the mesh is the bake's decision (:func:`meshshade.light.samples.entry_samples`).
"""
from __future__ import annotations

import numpy as np

from meshshade.errors import LightError
from meshshade.kernels.fresnel import fresnel_reflectance
from meshshade.light.samples import entry_samples
from meshshade.light.area import emitter_points
from meshshade.light.environment import map_sampler
from meshshade.light.sources import AreaLight, BeamLight, DirectionalLight, EnvironmentLight, PointLight, light_list
from meshshade.montecarlo.sampling import refract_in

#: share of the mean that every face keeps in the face distribution of an environment or area light (defensive
#: importance sampling: a face the bake's estimate missed can still be drawn, so the estimate stays unbiased)
DEFENSIVE_SHARE = 0.1

__all__ = ["Emitter"]


class Emitter:
    """Draws photons from the lights: entry point (face, bary), inward direction, weight (W), specular part.

    Every photon carries ``P_total / N`` W times a correction for point lights; shadowed directional/point
    photons, and photons of a wide beam that pass beside the mesh, carry no incident power (weight 0).

    Whether each light reaches the mesh is decided by the bake's own rule,
    :func:`meshshade.light.samples.entry_samples` (so ``mc`` and ``bake`` accept and refuse the same scenes): a
    beam that misses and a scene where no light reaches the mesh are errors, a light among several that reaches
    nothing is a warning (and emits nothing).

    Beams: a pencil beam enters at its first hit (float64); a beam of radius R > 0 is uniform over its disc: each
    photon starts at a uniform point of the part of the disc that can meet the mesh (the disc's square clipped to
    the mesh's projected bounding box; points outside the disc carry nothing) and enters where its ray first hits.

    Parameters
    ----------
    V : (n, 3) float64 mm; F : (m, 3) int64, outward faces
    normals : (m, 3) float64 unit outward face normals; areas : (m,) float64 mm^2 face areas
    lights : a light or a sequence of lights (BeamLight, DirectionalLight, PointLight, EnvironmentLight, AreaLight;
        validated by their constructors; anything else raises LightError, see
        :func:`meshshade.light.sources.light_list`)
    scene : EmbreeScene or NumpyScene of the mesh; eta : float, relative index of the medium
    bake_mesh : None, or ``(V, F, normals, areas, scene, walk_face, flipped)`` of the mesh the bake sees when the
        photons enter a different surface (the walk surface of :mod:`meshshade.montecarlo.boundary`, whose first
        vertices are that mesh's): which lights reach is then decided on that mesh, as the bake decides it, and
        its faces map to the surface's by ``walk_face`` (-1: none), wound the other way where ``flipped``

    Raises
    ------
    LightError
        No light; not a light; a beam or point light inside the mesh; a beam that misses the mesh or reaches the
        back of a face; no light reaching the mesh.
    """

    def __init__(self, V, F, normals, areas, lights, scene, eta, *, bake_mesh=None):
        self.V, self.F, self.N, self.A, self.scene, self.eta = V, F, normals, areas, scene, eta
        self.lights = light_list(lights)
        if not self.lights:
            raise LightError("Monte Carlo needs at least one light")
        # the bake's rule for what reaches the mesh (errors and warnings), on the same vertex normals and areas
        vn, va = _vertex_normals_areas(V, F, normals, areas)
        if bake_mesh is None:
            reach = entry_samples(V, F, vn, va, self.lights, scene, eta)
        else:
            bV, bF, bN, bA, b_scene, walk_face, flipped = bake_mesh
            reach = entry_samples(bV, bF, *_vertex_normals_areas(bV, bF, bN, bA), self.lights, b_scene, eta)
            reach = _on_surface(reach, walk_face, flipped)
        reached = np.bincount(reach.light_index, minlength=len(self.lights)) > 0
        self.parts = []
        power = []
        c = V[F].mean(axis=1)
        for i, light in enumerate(self.lights):
            if isinstance(light, BeamLight):
                o, d = np.array(light.origin), np.array(light.direction)
                hits = scene.first_hit(o, d, exact=True)
                f, bary = int(hits.face[0]), hits.bary[0]
                if f < 0 or float(normals[f] @ d) >= 0.0:   # a wide beam whose axis misses: its nearest entry
                    f, bary = _representative_entry(reach, i, o, d, F)
                if light.radius == 0.0:
                    self.parts.append(("beam", f, bary, d))
                    power.append(light.power)
                else:
                    rect = _disc_rect(light, V)
                    self.parts.append(("disc", f, bary, d, light, rect))
                    power.append(light.power * rect[4] / (np.pi * light.radius ** 2))
                continue
            if isinstance(light, (EnvironmentLight, AreaLight)):
                w = _quadrature_face_weights(reach, i, F, areas, va)
                total = float(w.sum())
                if not (reached[i] and total > 0.0):
                    w, total = np.zeros_like(w), 0.0
                self.parts.append(("sky", np.cumsum(w) / total if total > 0.0 else w, w, light))
                power.append(total)
                continue
            if isinstance(light, DirectionalLight):
                cos = normals @ (-np.array(light.direction))
                w = light.irradiance * np.clip(cos, 0.0, None) * areas
            else:
                pos = np.array(light.position)
                delta = pos - c
                r2 = np.einsum("ij,ij->i", delta, delta)
                cos = np.einsum("ij,ij->i", normals, delta) / np.sqrt(r2)
                w = light.emission(-delta) * np.clip(cos, 0.0, None) * areas / r2
            total = float(w.sum())
            if not (reached[i] and total > 0.0):   # warned about by entry_samples: it emits nothing
                w, total = np.zeros_like(w), 0.0
            self.parts.append(("area", np.cumsum(w) / total if total > 0.0 else w, w, light))
            power.append(total)
        self.light_power = np.array(power, dtype=np.float64)   # W (for area lights: centroid estimate)
        self.total_power = float(self.light_power.sum())
        if not (self.total_power > 0.0 and np.isfinite(self.total_power)):
            raise LightError("no light reaches the mesh's faces (the Monte Carlo result would be all zeros)")
        self.light_cdf = np.cumsum(self.light_power) / self.total_power
        # faces whose normal faces each light (diffuse reflectance vs transmittance)
        self.facing = np.zeros((len(self.lights), F.shape[0]), dtype=bool)
        for i, light in enumerate(self.lights):
            if isinstance(light, EnvironmentLight):   # light from everywhere: every exit is reflectance
                self.facing[i] = True
            elif isinstance(light, AreaLight):        # faces in front of the emitter, turned towards its centre
                pos, nrm = np.array(light.position), np.array(light.normal)
                self.facing[i] = ((np.einsum("ij,ij->i", normals, pos - c) > 0.0) & ((c - pos) @ nrm > 0.0))
            elif isinstance(light, PointLight):
                self.facing[i] = np.einsum("ij,ij->i", normals, np.array(light.position) - c) > 0.0
            else:
                self.facing[i] = normals @ (-np.array(light.direction)) > 0.0

    def emit(self, k: int, n_total: int, rng):
        """k photons: (light, face, points, dirs_in, weight_in, specular, incident).

        points are moved just inside the surface; weight_in = incident x (1 - F), specular = incident x F.
        """
        light = np.minimum(np.searchsorted(self.light_cdf, rng.random(k), side="right"), len(self.lights) - 1)
        face = np.zeros(k, dtype=np.int64)
        points = np.zeros((k, 3))
        dirs = np.zeros((k, 3))
        Fr = np.zeros(k)
        weight = np.full(k, self.total_power / n_total)
        for i, part in enumerate(self.parts):
            sel = np.flatnonzero(light == i)
            if sel.size == 0:
                continue
            if part[0] == "beam":   # one entry for all its photons
                f, b, d = part[1], part[2], part[3]
                p1, d1, F1 = self._enter(np.array([f]), np.asarray(b, dtype=np.float64)[None], np.asarray(d)[None])
                face[sel], points[sel], dirs[sel], Fr[sel] = f, p1[0], d1[0], F1[0]
                continue
            if part[0] == "disc":
                self._emit_disc(part, sel, rng, face, points, dirs, Fr, weight)
                continue
            if part[0] == "sky":
                self._emit_sky(part, sel, rng, face, points, dirs, Fr, weight)
                continue
            _, cdf, w_face, lt = part
            f = np.minimum(np.searchsorted(cdf, rng.random(sel.size), side="right"), cdf.size - 1)
            r1, r2 = np.sqrt(rng.random(sel.size)), rng.random(sel.size)
            b = np.stack([1.0 - r1, r1 * (1.0 - r2), r1 * r2], axis=1)
            p = np.einsum("ij,ijk->ik", b, self.V[self.F[f]])
            if isinstance(lt, DirectionalLight):
                d = np.broadcast_to(np.array(lt.direction), (sel.size, 3))
                to_light, t_max = -d, np.inf
            else:
                delta = p - np.array(lt.position)
                dist = np.linalg.norm(delta, axis=1)
                d = delta / dist[:, None]
                to_light, t_max = -d, dist
                # importance weight: true irradiance at the point over the face-centroid value used for sampling
                cos = np.clip(-np.einsum("ij,ij->i", self.N[f], d), 0.0, None)
                weight[sel] *= lt.emission(delta) * cos / dist ** 2 * self.A[f] / w_face[f]
            origin = self.scene.offset_origins(p, self.N[f], sign=1.0)
            shadow = self.scene.occluded(origin, to_light, t_max)
            weight[sel[shadow]] = 0.0
            face[sel] = f
            points[sel], dirs[sel], Fr[sel] = self._enter(f, b, d)
        return light, face, points, dirs, weight * (1.0 - Fr), weight * Fr, weight.copy()

    def _emit_disc(self, part, sel, rng, face, points, dirs, Fr, weight):
        """Photons ``sel`` of a beam of radius > 0: uniform over the clipped square of its disc, cast along the
        beam; those outside the disc or passing beside the mesh carry nothing (they hold face 0, weight 0)."""
        _, _, _, d, lt, (u, v, lo, hi, _area) = part
        ab = lo + (hi - lo) * np.stack([rng.random(sel.size), rng.random(sel.size)], axis=1)
        inside = np.einsum("ij,ij->i", ab, ab) <= lt.radius ** 2
        origins = np.array(lt.origin) + ab[:, :1] * u + ab[:, 1:] * v
        hit = np.zeros(sel.size, dtype=bool)
        f = np.zeros(sel.size, dtype=np.int64)
        bary = np.zeros((sel.size, 3))
        cast = np.flatnonzero(inside)
        if cast.size:
            h = self.scene.first_hit(origins[cast], np.broadcast_to(d, (cast.size, 3)))
            ok = h.face >= 0
            ok[ok] = self.N[h.face[ok]] @ d < 0.0
            hit[cast[ok]] = True
            f[cast[ok]], bary[cast[ok]] = h.face[ok], h.bary[ok]
        weight[sel[~hit]] = 0.0
        face[sel] = f
        if np.any(hit):
            idx = np.flatnonzero(hit)
            p1, d1, F1 = self._enter(f[idx], bary[idx], np.broadcast_to(d, (idx.size, 3)))
            points[sel[idx]], dirs[sel[idx]], Fr[sel[idx]] = p1, d1, F1

    def _emit_sky(self, part, sel, rng, face, points, dirs, Fr, weight):
        """Photons ``sel`` of an environment or area light: a face from the light's face distribution, a uniform
        point on it, a direction as the bake's quadrature draws it (module docstring of
        :mod:`meshshade.light.sky_loops`), weighted by integrand / density; shadowed ones carry nothing."""
        _, cdf, w_face, lt = part
        k = sel.size
        f = np.minimum(np.searchsorted(cdf, rng.random(k), side="right"), cdf.size - 1)
        r1, r2 = np.sqrt(rng.random(k)), rng.random(k)
        b = np.stack([1.0 - r1, r1 * (1.0 - r2), r1 * r2], axis=1)
        p = np.einsum("ij,ijk->ik", b, self.V[self.F[f]])
        nf = self.N[f]
        if isinstance(lt, EnvironmentLight):
            sampler = map_sampler(lt)
            strategy = rng.random(k) < 0.5
            x, y = rng.random(k), rng.random(k)
            w = np.where(strategy[:, None], sampler.sample(x, y), _cosine(nf, x, y))
            cos = np.clip(np.einsum("ij,ij->i", w, nf), 0.0, None)
            pdf = 0.5 * sampler.pdf(w) + 0.5 * cos / np.pi
            value = sampler.radiance(w) * cos / np.where(pdf > 0.0, pdf, 1.0)
            t_max = np.inf
        else:
            y_pt = emitter_points(lt, rng.random(k), rng.random(k))
            delta = y_pt - p
            dist = np.linalg.norm(delta, axis=1)
            w = delta / dist[:, None]
            cos = np.clip(np.einsum("ij,ij->i", w, nf), 0.0, None)
            cos_e = np.clip(-(w @ np.array(lt.normal)), 0.0, None)
            value = lt.area * lt.radiance * cos * cos_e / dist ** 2
            t_max = dist
        weight[sel] *= value * self.A[f] / w_face[f]
        origin = self.scene.offset_origins(p, nf, sign=1.0)
        lit = weight[sel] > 0.0
        shadow = np.zeros(k, dtype=bool)
        if np.any(lit):
            tm = t_max if np.isscalar(t_max) else t_max[lit]
            shadow[lit] = self.scene.occluded(origin[lit], w[lit], tm)
        weight[sel[shadow]] = 0.0
        face[sel] = f
        points[sel], dirs[sel], Fr[sel] = self._enter(f, b, -w)

    def _enter(self, face, bary, d_out):
        """Entry of photons arriving along d_out (n, 3) at (face, bary): (point just inside, refracted direction,
        Fresnel reflectance F(cos_i) from index 1 into eta)."""
        points = np.einsum("ij,ijk->ik", bary, self.V[self.F[face]])
        n = self.N[face]
        cos_i = np.clip(-np.einsum("ij,ij->i", d_out, n), 0.0, 1.0)
        Fr = fresnel_reflectance(cos_i, 1.0, self.eta)
        return self.scene.offset_origins(points, n, sign=-1.0), refract_in(d_out, n, self.eta), Fr


def _cosine(n, x, y) -> np.ndarray:
    """(k, 3) cosine-weighted unit directions about the unit normals ``n`` (k, 3) for (x, y) in [0, 1)^2."""
    s = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (s + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t1 = np.stack([1.0 + s * n[:, 0] ** 2 * a, s * b, -s * n[:, 0]], axis=1)
    t2 = np.stack([b, s + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    r, phi = np.sqrt(x), 2.0 * np.pi * y
    z = np.sqrt(np.clip(1.0 - x, 0.0, None))
    return (r * np.cos(phi))[:, None] * t1 + (r * np.sin(phi))[:, None] * t2 + z[:, None] * n


def _quadrature_face_weights(samples, i, F, face_areas, vertex_areas) -> np.ndarray:
    """(m,) W: the face distribution of environment or area light ``i``, from the bake's entry samples: each face's
    area times the mean of its vertices' incident irradiance (entering power over area, scaled by the light's
    incident over entering power), plus :data:`DEFENSIVE_SHARE` of the area-weighted mean irradiance."""
    j = samples.light_index == i
    n = vertex_areas.shape[0]
    enter = np.bincount(samples.vertex[j], weights=samples.power[j], minlength=n)
    total = float(enter.sum())
    if not total > 0.0:
        return np.zeros(F.shape[0])
    scale = float(samples.incident_power[i]) / total
    E = scale * np.divide(enter, vertex_areas, out=np.zeros(n), where=vertex_areas > 0.0)
    Ef = E[F].mean(axis=1)
    mean = float(np.sum(Ef * face_areas) / max(float(face_areas.sum()), 1e-300))
    return face_areas * (Ef + DEFENSIVE_SHARE * mean)


def _vertex_normals_areas(V, F, face_normals, face_areas):
    """Area-weighted unit vertex normals and barycentric vertex areas (a third of each incident face), as
    :class:`~meshshade.geometry.mesh.Mesh` defines them, from the face normals and areas the emitter is given."""
    idx = F.reshape(-1)
    w = np.repeat(face_areas, 3)
    acc = np.stack([np.bincount(idx, weights=np.repeat(face_normals[:, j], 3) * w, minlength=V.shape[0])
                    for j in range(3)], axis=1)
    norm = np.linalg.norm(acc, axis=1, keepdims=True)
    vn = np.divide(acc, norm, out=np.zeros_like(acc), where=norm > 0)
    return vn, np.bincount(idx, weights=w / 3.0, minlength=V.shape[0])


def _on_surface(samples, walk_face, flipped):
    """The bake's entry samples with their faces moved onto the walk surface (-1 where the face is not on it,
    barycentrics reordered where it is wound the other way); vertices are the same (the surface's come first)."""
    from dataclasses import replace

    face = np.asarray(samples.face, dtype=np.int64)
    on = face >= 0
    wf = np.where(on, walk_face[np.maximum(face, 0)], -1)
    bary = np.array(samples.bary, dtype=np.float64, copy=True)
    flip = np.flatnonzero(wf >= 0)
    flip = flip[flipped[wf[flip]]]
    bary[flip] = bary[flip][:, [0, 2, 1]]
    return replace(samples, face=wf, bary=bary)


def _representative_entry(samples, i, o, d, F):
    """(face, bary) of light ``i``'s entry sample nearest its axis (a wide beam whose axis passes beside the
    mesh): the reference point of the beam's radial tallies."""
    j = np.flatnonzero(samples.light_index == i)
    rel = samples.positions[j] - o
    perp = rel - np.outer(rel @ d, d)
    j = int(j[np.argmin(np.einsum("ij,ij->i", perp, perp))])
    if samples.face[j] >= 0:
        return int(samples.face[j]), samples.bary[j]
    v = int(samples.vertex[j])
    around = np.flatnonzero(np.any(F == v, axis=1))
    if around.size == 0:    # the vertex is on no face the photons enter (a transparent face's): any face
        return 0, np.array([1.0, 0.0, 0.0])
    f = int(around[0])
    return f, (F[f] == v).astype(np.float64)


def _disc_rect(light, V):
    """Where photons of a wide beam start: ``(u, v, lo, hi, area)``, the beam's plane basis and the square
    [-R, R]^2 of its disc clipped to the bounding box of the mesh's projection on that plane (no photon is drawn
    where no ray can meet the mesh); ``area`` in mm^2."""
    u, v = light.disc_basis()
    rel = V - np.array(light.origin)
    ab = np.stack([rel @ u, rel @ v], axis=1)
    lo = np.maximum(ab.min(axis=0), -light.radius)
    hi = np.minimum(ab.max(axis=0), light.radius)
    hi = np.maximum(hi, lo)
    return u, v, lo, hi, float(np.prod(hi - lo))
