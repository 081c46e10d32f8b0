"""The Monte Carlo photon emitter: photons drawn from the lights, Fresnel-split and refracted into the medium.

At entry the unpolarised Fresnel reflectance F(cos) (index 1 outside, ``eta`` inside) is split off
deterministically as specular power and the rest is refracted (Snell) into the medium. A beam enters at its
first hit (float64); directional and point lights are sampled over the faces in proportion to the incident
power at the face centroids (point lights then carry an importance weight), and shadowed photons carry no power.
"""
from __future__ import annotations

import numpy as np

from meshshade.errors import LightError
from meshshade.kernels.fresnel import fresnel_reflectance
from meshshade.light.sources import BeamLight, DirectionalLight, PointLight, check_outside_mesh, light_list
from meshshade.montecarlo.sampling import refract_in

__all__ = ["Emitter"]


class Emitter:
    """Draws photons from the lights: entry point (face, bary), inward direction, weight (W), specular part.

    Every photon carries ``P_total / N`` W times a correction for point lights; shadowed directional/point
    photons carry no incident power (weight 0).

    Parameters
    ----------
    V : (n, 3) float64 mm; F : (m, 3) int64, outward faces
    normals : (m, 3) float64 unit outward face normals; areas : (m,) float64 mm^2 face areas
    lights : a light or a sequence of BeamLight / DirectionalLight / PointLight (validated by their
        constructors; anything else raises LightError, see :func:`meshshade.light.sources.light_list`)
    scene : EmbreeScene or NumpyScene of the mesh; eta : float, relative index of the medium

    Raises
    ------
    LightError
        No light; not a light; a beam or point light inside the mesh; a beam that misses the mesh or reaches the
        back of a face; a directional or point light that faces no part of the mesh.
    """

    def __init__(self, V, F, normals, areas, lights, scene, eta):
        self.V, self.F, self.N, self.A, self.scene, self.eta = V, F, normals, areas, scene, eta
        self.lights = light_list(lights)
        if not self.lights:
            raise LightError("Monte Carlo needs at least one light")
        self.parts = []
        power = []
        for i, light in enumerate(self.lights):
            check_outside_mesh(light, i, V, F)
            if isinstance(light, BeamLight):
                o, d = np.array(light.origin), np.array(light.direction)
                hits = scene.first_hit(o, d, exact=True)
                f = int(hits.face[0])
                if f < 0 or float(normals[f] @ d) >= 0.0:
                    raise LightError(f"beam light {i} from {light.origin} mm along {light.direction} misses "
                                     "the mesh (or reaches the back of a face)")
                self.parts.append(("beam", f, hits.bary[0], d))
                power.append(light.power)
            else:
                c = V[F].mean(axis=1)
                if isinstance(light, DirectionalLight):
                    cos = normals @ (-np.array(light.direction))
                    w = light.irradiance * np.clip(cos, 0.0, None) * areas
                else:
                    pos = np.array(light.position)
                    delta = pos - c
                    r2 = np.einsum("ij,ij->i", delta, delta)
                    cos = np.einsum("ij,ij->i", normals, delta) / np.sqrt(r2)
                    w = light.intensity * np.clip(cos, 0.0, None) * areas / r2
                total = float(w.sum())
                if not total > 0.0:
                    raise LightError(f"light {i} ({light!r}) faces no part of the mesh")
                self.parts.append(("area", np.cumsum(w) / total, w, light))
                power.append(total)
        self.light_power = np.array(power, dtype=np.float64)   # W (for area lights: centroid estimate)
        self.total_power = float(self.light_power.sum())
        self.light_cdf = np.cumsum(self.light_power) / self.total_power
        # faces whose normal faces each light (diffuse reflectance vs transmittance)
        self.facing = np.zeros((len(self.lights), F.shape[0]), dtype=bool)
        c = V[F].mean(axis=1)
        for i, light in enumerate(self.lights):
            if isinstance(light, PointLight):
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
                weight[sel] *= lt.intensity * cos / dist ** 2 * self.A[f] / w_face[f]
            origin = self.scene.offset_origins(p, self.N[f], sign=1.0)
            shadow = self.scene.occluded(origin, to_light, t_max)
            weight[sel[shadow]] = 0.0
            face[sel] = f
            points[sel], dirs[sel], Fr[sel] = self._enter(f, b, d)
        return light, face, points, dirs, weight * (1.0 - Fr), weight * Fr, weight.copy()

    def _enter(self, face, bary, d_out):
        """Entry of photons arriving along d_out (n, 3) at (face, bary): (point just inside, refracted direction,
        Fresnel reflectance F(cos_i) from index 1 into eta)."""
        points = np.einsum("ij,ijk->ik", bary, self.V[self.F[face]])
        n = self.N[face]
        cos_i = np.clip(-np.einsum("ij,ij->i", d_out, n), 0.0, 1.0)
        Fr = fresnel_reflectance(cos_i, 1.0, self.eta)
        return self.scene.offset_origins(points, n, sign=-1.0), refract_in(d_out, n, self.eta), Fr
