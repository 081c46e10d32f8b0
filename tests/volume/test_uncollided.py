"""The light that crosses the object unscattered (docs/physics.md §15.6, eqs. (130)-(131);
meshshade/volume/uncollided.py), against closed forms and adding-doubling.

References, each from its own route:
* a slab of optical thickness tau lit at normal incidence leaves on its far face, per unit of entering irradiance,
  (1 - r) e^{-tau} / (1 - r^2 e^{-2 tau}), r the Fresnel reflectance at normal incidence from inside (the geometric
  series of the reflections between the faces);
* a sphere of radius a: a ray entering at angle theta_i crosses chords of one length 2 a cos theta_t, each ending at
  the same angle inside, so it leaves with (1 - R) e^{-tau} / (1 - R e^{-tau}), tau = sigma 2 a cos theta_t, R the
  Fresnel reflectance at theta_t; integrated over the lit disc with scipy's quad;
* a 2 mm slab of ketchup: adding-doubling's total transmission (iadpython, independent of meshshade), whose green
  and blue are nearly all unscattered light (reduced albedo 0.07 and 0.02).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from scipy.integrate import quad

from meshshade.geometry.mesh import Mesh
from meshshade.kernels.fresnel import refract_in
from meshshade.light import DirectionalLight, entry_samples
from meshshade.materials import Material
from meshshade.raycast import make_scene
from meshshade.volume.inside import SurfaceVolume
from meshshade.volume.uncollided import FLOOR, face_entries, uncollided_exitance

ETA = 1.4


def _fresnel(cos_i, n1, n2):
    """Unpolarised Fresnel reflectance written out here (Born & Wolf), not the package's."""
    sin_t = n1 / n2 * math.sqrt(max(0.0, 1.0 - cos_i * cos_i))
    if sin_t >= 1.0:
        return 1.0
    cos_t = math.sqrt(1.0 - sin_t * sin_t)
    rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
    rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i)
    return 0.5 * (rs * rs + rp * rp)


def _slab(size, height, levels):
    box = trimesh.creation.box(extents=(size, size, height))
    for _ in range(levels):
        box = box.subdivide()
    return np.asarray(box.vertices, dtype=np.float64), np.asarray(box.faces, dtype=np.int64)


def _top_entries(V, F, height):
    """Entries at the top face's vertices off its rim, straight down, each the power of its vertex's area (unit
    irradiance)."""
    mesh = Mesh.from_arrays(V, F)
    rim = np.max(np.abs(V[:, :2]), axis=1) > np.max(np.abs(V[:, 0])) - 1e-9
    top = np.flatnonzero((np.abs(V[:, 2] - height / 2) < 1e-9) & ~rim)
    pos = V[top]
    n = np.tile([0.0, 0.0, 1.0], (len(top), 1))
    d = np.tile([0.0, 0.0, -1.0], (len(top), 1))
    return mesh, pos, n, d, mesh.vertex_areas[top]


@pytest.mark.parametrize("sigma", [0.3, 1.5])
def test_a_slab_lets_the_unscattered_light_through_as_the_series_of_reflections(sigma):
    height = 2.0
    V, F = _slab(20.0, height, 4)
    mesh, pos, n, d, power = _top_entries(V, F, height)
    scene = make_scene(V, F)
    M, stats = uncollided_exitance(scene, mesh.vertex_areas, pos, n, d, power, ETA, sigma_t_prime=np.full(3, sigma),
                                   floor=1e-15)
    r = _fresnel(1.0, ETA, 1.0)
    tau = sigma * height
    back = (1 - r) * math.exp(-tau) / (1 - r * r * math.exp(-2 * tau))
    front = (1 - r) * r * math.exp(-2 * tau) / (1 - r * r * math.exp(-2 * tau))
    centre = np.hypot(V[:, 0], V[:, 1]) < 5.0
    bottom = centre & (np.abs(V[:, 2] + height / 2) < 1e-9)
    top = centre & (np.abs(V[:, 2] - height / 2) < 1e-9)
    # to 1e-4: each segment starts off the surface by the ray scene's offset (about 3e-5 mm here)
    np.testing.assert_allclose(M[bottom], back, rtol=1e-4)
    np.testing.assert_allclose(M[top], front, rtol=1e-4)
    # every watt is accounted for: what left plus what the slab absorbed on the way
    absorbed = power.sum() * (1 - math.exp(-tau)) * (1 + r * math.exp(-tau)) / (1 - r * r * math.exp(-2 * tau))
    np.testing.assert_allclose(stats["left"] + absorbed, power.sum(), rtol=1e-4)
    # the default floor stops a ray under FLOOR of its power: what it leaves out is less than that
    M_d, _ = uncollided_exitance(scene, mesh.vertex_areas, pos, n, d, power, ETA, sigma_t_prime=np.full(3, sigma))
    assert np.all(np.abs(M_d[top] - M[top]) <= FLOOR * 1.0) and np.all(M_d[top] <= M[top])


def test_a_sphere_lets_through_its_chords_light_integrated_over_the_disc():
    a, sigma = 3.0, 0.4
    ico = trimesh.creation.icosphere(subdivisions=5, radius=a)
    V, F = np.asarray(ico.vertices), np.asarray(ico.faces)
    mesh = Mesh.from_arrays(V, F)
    scene = make_scene(V, F)
    sun = DirectionalLight((0.0, 0.0, -1.0), 1.0)
    smp = entry_samples(V, F, mesh.vertex_normals, mesh.vertex_areas, [sun], scene=scene, eta=ETA)
    w = refract_in(smp.directions, smp.normals, ETA)
    _, stats = uncollided_exitance(scene, mesh.vertex_areas, smp.positions, smp.normals, w, smp.power, ETA,
                                   sigma_t_prime=np.full(3, sigma))

    def out(b):
        cos_i = math.sqrt(1.0 - (b / a) ** 2)
        sin_t = math.sqrt(1.0 - cos_i ** 2) / ETA
        cos_t = math.sqrt(1.0 - sin_t ** 2)
        R = _fresnel(cos_t, ETA, 1.0)
        tau = sigma * 2 * a * cos_t
        return 2 * math.pi * b * (1 - _fresnel(cos_i, 1.0, ETA)) * (1 - R) * math.exp(-tau) / (1 - R * math.exp(-tau))

    expected = quad(out, 0.0, a, limit=200, epsabs=0, epsrel=1e-10)[0]
    np.testing.assert_allclose(stats["left"], expected, rtol=0.01)


def test_faces_with_the_medium_on_both_sides_are_crossed_and_a_hole_lets_light_out():
    """Two overlapping slabs (z in [-1, 0.2] and [-0.2, 1]) are one slab of 2 mm: their inner faces are crossed
    without a Fresnel event (the winding number on both sides above 1/2); the top slab alone with its bottom face
    removed (an opening) loses what would have crossed it."""
    sigma, height = 0.5, 2.0
    Va, Fa = _slab(20.0, 1.2, 4)
    lower = Va + [0.0, 0.0, -0.4]
    upper = Va + [0.0, 0.0, 0.4]
    V = np.concatenate([lower, upper])
    F = np.concatenate([Fa, Fa + len(Va)])
    mesh, pos, n, d, power = _top_entries(V, F, height)
    inside = SurfaceVolume(V, F)
    M, stats = uncollided_exitance(make_scene(V, F), mesh.vertex_areas, pos, n, d, power, ETA,
                                   sigma_t_prime=np.full(3, sigma), sides=lambda p: inside.winding(p) > 0.5)
    r = _fresnel(1.0, ETA, 1.0)
    tau = sigma * height
    centre = np.hypot(V[:, 0], V[:, 1]) < 5.0
    bottom = centre & (np.abs(V[:, 2] + height / 2) < 1e-9)
    np.testing.assert_allclose(M[bottom], (1 - r) * math.exp(-tau) / (1 - r * r * math.exp(-2 * tau)), rtol=1e-4)
    # the inner faces (z = 0.2 of the lower slab, z = -0.2 of the upper) take nothing
    inner = np.abs(np.abs(V[:, 2]) - 0.2) < 1e-9
    assert np.all(M[inner] == 0.0)

    keep = ~np.all(np.abs(upper[Fa][:, :, 2] - (0.4 - 0.6)) < 1e-9, axis=1)      # the upper slab's bottom removed
    Fo = Fa[keep]
    open_mesh = Mesh.from_arrays(upper, Fo)
    inside_o = SurfaceVolume(upper, Fo)
    _, pos, n, d, power = _top_entries(upper, Fo, height)
    Mo, so = uncollided_exitance(make_scene(upper, Fo), open_mesh.vertex_areas, pos, n, d, power, ETA,
                                 sigma_t_prime=np.full(3, sigma), sides=lambda p: inside_o.winding(p) > 0.5)
    # nothing leaves through the missing face onto a face beyond it: the light that reached it is lost
    assert so["lost"][0] > 0.3 * power.sum() * math.exp(-sigma * 1.2)
    assert so["left"][0] < 0.1 * power.sum() * math.exp(-sigma * 1.2)


def test_face_entries_split_each_vertex_s_power_over_its_lit_faces_as_photons_enter():
    """Each vertex's entry becomes one per face facing the light, at the centroid of the vertex's third of it,
    refracted by the face's own normal, their powers in the ratio A_f/3 cos_f F_t(cos_f) and summing to the
    vertex's; a beam's point entry is kept as it is."""
    ico = trimesh.creation.icosphere(subdivisions=2, radius=5.0)
    V, F = np.asarray(ico.vertices), np.asarray(ico.faces)
    mesh = Mesh.from_arrays(V, F)
    sun = np.array([0.3, -0.4, -0.866]) / np.linalg.norm([0.3, -0.4, -0.866])
    v = np.flatnonzero(mesh.vertex_normals @ -sun > 0.2)
    k = v.size
    vertex = np.concatenate([v, [-1]])
    positions = np.concatenate([V[v], [[0.0, 0.0, 5.0]]])
    normals = np.concatenate([mesh.vertex_normals[v], [[0.0, 0.0, 1.0]]])
    directions = np.tile(sun, (k + 1, 1))
    power = np.linspace(1.0, 2.0, k + 1)
    pos, nrm, win, pw = face_entries(V, F, vertex, positions, directions, normals, power, ETA)
    assert math.isclose(pw.sum(), power.sum(), rel_tol=1e-12)
    # the beam's entry, last of the kept ones, as it was
    np.testing.assert_array_equal(pos[-1], positions[-1])
    assert pw[-1] == power[-1]
    # one vertex's split, written out from its faces
    i = 7
    faces = np.flatnonzero(np.any(F == v[i], axis=1))
    tri = V[F[faces]]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    a = 0.5 * np.linalg.norm(n, axis=1)
    n /= 2 * a[:, None]
    cos = n @ -sun
    t = np.array([1.0 - _fresnel(c, 1.0, ETA) for c in cos])
    share = a / 3 * cos * t * (cos > 0)
    want_pos = (2.0 / 3.0) * V[v[i]] + (tri.sum(axis=1) - V[v[i]]) / 6.0
    got = {tuple(np.round(p, 9)): (q, d) for p, q, d in zip(pos, pw, win)}
    for p_, s_, n_ in zip(want_pos, share, n):
        if s_ <= 0:
            continue
        q, d = got[tuple(np.round(p_, 9))]
        assert math.isclose(q, s_ / share.sum() * power[i], rel_tol=1e-9)
        sin_t = np.linalg.norm(np.cross(d, n_))                      # Snell at the face's own normal
        assert math.isclose(sin_t * ETA, np.linalg.norm(np.cross(sun, n_)), rel_tol=1e-9)


@pytest.mark.slow
def test_a_thin_ketchup_slab_transmits_what_adding_doubling_transmits():
    """A 20 x 20 x 2 mm box of ketchup under a sun at normal incidence: the exitance at the middle of its far face
    against adding-doubling's total transmission of a 2 mm slab in air (iadpython, 32 quadrature points), green and
    blue (nearly all unscattered); without the unscattered light the far face is dark (-98 / -99 %)."""
    import iadpython as iad

    from meshshade.transport import bake
    from meshshade.transport.options import BakeOptions
    from meshshade.volume.options import VolumeOptions

    size, height = 20.0, 2.0
    V, F = _slab(size, height, 5)
    V = V + np.array([0.37, 0.23, 0.11])                        # off the lattice's planes (docs/limitations.md)
    with pytest.warns(Warning, match="diffusion theory is inaccurate"):       # its green and blue albedos
        mat = Material.preset("ketchup")
    back = (np.abs(V[:, 2] - (-height / 2 + 0.11)) < 1e-9) & (np.hypot(V[:, 0] - 0.37, V[:, 1] - 0.23) < 3.0)
    sun = DirectionalLight((0.0, 0.0, -1.0), 1.0)
    expected = []
    for c in (1, 2):
        ss, sa = float(mat.sigma_s_prime[c]), float(mat.sigma_a[c])
        sample = iad.Sample(a=ss / (ss + sa), b=(ss + sa) * height, g=0.0, n=float(mat.eta), n_above=1.0,
                            n_below=1.0, quad_pts=32)
        expected.append(float(sample.rt()[1]))
    got = bake(Mesh.from_arrays(V, F), mat, [sun], BakeOptions(progress=False)).radiance[back].mean(axis=0)
    np.testing.assert_allclose(got[1:], expected, rtol=0.02)


def test_parts_of_different_extinction_take_each_part_s_along_the_ray():
    """Two hemispheres of 4 mm, skin1 (x > 0) and ketchup (x < 0; red's sigma_t' 0.77 against 0.24 /mm), a sun
    along -x: every ray crosses from one into the other. The bake's term (the parts' medium sampled by the midpoint
    rule along each segment) against the same rays with the optical depth split exactly at the plane x = 0; the
    inner caps are crossed, not exits."""
    from meshshade.geometry.procedural import split_sphere
    from meshshade.parts import PartedMaterial
    from meshshade.volume.transport import VolumeTransport

    V, F, part = split_sphere(4.0, (1.0, 0.0, 0.0), 16)
    with pytest.warns(Warning):
        mesh = Mesh.from_arrays(V, F)
        skin, ketchup = Material.preset("skin1"), Material.preset("ketchup")
    pm = PartedMaterial([skin, ketchup], part, ["skin", "ketchup"])
    vt = VolumeTransport.build(pm.oriented(mesh), pm)
    S = vt.surface.samples
    scene = make_scene(S.vertices, S.faces)
    smp = entry_samples(S.vertices, S.faces, S.vertex_normals, S.vertex_areas,
                        [DirectionalLight((-1.0, 0.0, 0.0), 1.0)], scene=scene, eta=float(skin.eta))
    M, stats = vt.uncollided(smp, scene)
    a, b = np.asarray(skin.sigma_t_prime), np.asarray(ketchup.sigma_t_prime)

    def exact(o, d, L):
        end = o + L[:, None] * d
        # the length with x > 0 of each segment (a straight segment meets the plane once)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.clip(np.where(d[:, 0] != 0.0, -o[:, 0] / d[:, 0], np.inf), 0.0, L)
        pos_first = o[:, 0] > 0.0
        L_pos = np.where(pos_first, s, L - s)
        L_pos = np.where((o[:, 0] > 0.0) == (end[:, 0] > 0.0), np.where(pos_first, L, 0.0), L_pos)
        return np.outer(L_pos, a) + np.outer(L - L_pos, b)
    exact.sigma_min = np.minimum(a, b)
    inside = vt.inside
    pos, nrm, win, pw = face_entries(S.vertices, S.faces, smp.vertex, smp.positions, smp.directions, smp.normals,
                                     smp.power, float(skin.eta))
    M_ref, ref = uncollided_exitance(scene, S.vertex_areas, pos, nrm, win, pw, float(skin.eta), optical_depth=exact,
                                     sides=lambda p: inside.winding(p) > 0.5)
    total = smp.power.sum()
    np.testing.assert_allclose(stats["volume_uncollided_power"], ref["left"] / total, rtol=0.02, atol=1e-6)
    assert ref["left"][0] > 0.01 * total                      # red crosses: the comparison means something
    # what one medium alone would let through differs by far more than the tolerance
    assert abs(np.exp(-(a[0] - b[0]) * 4.0) - 1.0) > 0.5
