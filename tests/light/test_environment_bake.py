"""Issue 43's linearity targets for the default bake (meshshade.transport.bake): they hold for any transport that
is linear in its sources, so they check what the environment light hands the transport.

* A uniform sky of radiance L on a closed convex mesh equals the sum of bakes under 256 directional lights on a
  spherical Fibonacci set (Gonzalez 2010: z_k = 1 - (2k + 1)/N, azimuth k x the golden angle), each of irradiance
  L 4 pi / 256 (the sphere's solid angle shared equally: the lights are a quadrature of the same sky), within
  1 % mean and 3 % at the 99th percentile over the (all lit) vertices.
* A map that holds one small bright disc equals a directional light of the same irradiance, within 2 % mean over
  the vertices that see the whole disc; the irradiance is the disc's pixels' integral of L cos, by this file's
  own midpoint quadrature over each pixel (the map is piecewise constant over its pixels).

Planted bugs these catch (each checked to fail): the four samples of a vertex replaced by one along its normal
(sources deeper than the fan's; one along the normalised mean refracted direction was measured 3-10 % low); the
Fresnel transmittance left out of the environment's entering power (both tests); the Y-up axis conversion turned
the wrong way (the disc test: the disc lights another side).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.light import DirectionalLight, EnvironmentLight
from meshshade.materials import Material
from meshshade.transport import bake

pytestmark = pytest.mark.slow


def fibonacci(n):
    k = np.arange(n)
    z = 1.0 - (2.0 * k + 1.0) / n
    phi = k * math.pi * (3.0 - math.sqrt(5.0))
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def test_uniform_sky_is_the_sum_of_256_directional_lights():
    mesh = Mesh.from_arrays(*icosphere(10.0, 3))
    mat = Material.preset("skin1")
    L = 2e-3
    sky = bake(mesh, mat, [EnvironmentLight.uniform(L)]).radiance
    suns = bake(mesh, mat, [DirectionalLight(tuple(-d), L * 4.0 * math.pi / 256) for d in fibonacci(256)]).radiance
    rel = np.abs(sky / suns - 1.0)
    assert np.all(rel.mean(axis=0) < 0.01), rel.mean(axis=0)
    assert np.all(np.percentile(rel, 99, axis=0) < 0.03), np.percentile(rel, 99, axis=0)


def _disc_map(H, centre, radius_deg, L, sub=24):
    """(map (H, 2H), irradiance on a plane facing ``centre``): pixels whose centre lies within ``radius_deg`` of
    the unit direction ``centre`` (a Y-up mesh frame, no rotation) hold L; the irradiance integral of L cos over
    them by a midpoint rule in (cos theta, phi) inside each pixel."""
    W = 2 * H
    s = (np.arange(H) + 0.5) / H
    u = (np.arange(W) + 0.5) / W
    theta, phi = np.pi * s[:, None], np.pi - 2.0 * np.pi * u[None, :]
    b = np.stack(np.broadcast_arrays(np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)), -1)
    w = np.stack([b[..., 0], b[..., 2], -b[..., 1]], -1)          # Blender (x, y, z) -> Y-up (x, z, -y)
    inside = w @ centre > math.cos(math.radians(radius_deg))
    Y = np.where(inside, L, 0.0)
    E = 0.0
    a = (np.arange(sub) + 0.5) / sub
    for r, c in zip(*np.nonzero(inside)):
        c0, c1 = math.cos(math.pi * r / H), math.cos(math.pi * (r + 1) / H)
        ct = c0 + a * (c1 - c0)
        st = np.sqrt(1 - ct * ct)
        ph = math.pi - 2 * math.pi * (c + a) / W
        bx, by, bz = np.outer(st, np.cos(ph)), np.outer(st, np.sin(ph)), np.outer(ct, np.ones(sub))
        cosine = np.clip(bx * centre[0] + bz * centre[1] - by * centre[2], 0, None)
        E += L * cosine.sum() * (2 * math.pi / W) * (c0 - c1) / sub ** 2
    return Y, E


def test_a_small_bright_disc_in_the_map_is_a_directional_light():
    mesh = Mesh.from_arrays(*icosphere(10.0, 3))
    mat = Material.preset("skin1")
    s = np.array([0.3, 0.8, -0.5])
    s /= np.linalg.norm(s)
    radius = 2.0
    Y, E = _disc_map(128, s, radius, 1.0)
    assert 0.5 * math.pi * math.radians(radius) ** 2 < E < 2.0 * math.pi * math.radians(radius) ** 2
    env = bake(mesh, mat, [EnvironmentLight(Y)]).radiance
    sun = bake(mesh, mat, [DirectionalLight(tuple(-s), E)]).radiance
    sees_all = mesh.vertex_normals @ s > math.sin(math.radians(3 * radius))
    rel = np.abs(env[sees_all] / sun[sees_all] - 1.0)
    assert np.all(rel.mean(axis=0) < 0.02), rel.mean(axis=0)
