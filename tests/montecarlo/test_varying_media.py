"""The Monte Carlo walk in a varying medium (issue 49): a painted material and a material of parts
(:mod:`meshshade.montecarlo.media`, :mod:`meshshade.montecarlo.varying_walk`).

* the medium the walk reads, point by point, against independent routes: libigl's closest point on the mesh, the
  paint's own numpy lookup (PaintedMaterial.colour_at) and eq. (106) solved directly (painted); the record's own
  numpy lookup PartedMaterial.part_at (parts, through the label grid and past it);
* a paint whose colour is everywhere the preset's own diffuse reflectance (eq. (105) at its albedo) is the preset:
  with g = 0 the painted walk draws the same numbers as the homogeneous one (sigma_t constant, no null collision),
  so the two runs agree bitwise when the table returns the preset's albedo, and to the table's error otherwise;
  with g != 0 (delta tracking) they agree statistically;
* parts of one material are the material: bitwise at the natural majorant, statistically with a majorant three
  times too high (null collisions);
* a sphere with a core of another medium against a separately written numpy random walk (analog absorption,
  regular tracking across the exact spheres, no Fresnel at eta = 1): reflectance, transmittance and absorption
  within 4 standard errors of both runs plus the polyhedral spheres' own difference.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from meshshade.geometry.mesh import Mesh, MeshDefectWarning
from meshshade.geometry.procedural import icosphere, spherical_uv, uv_sphere
from meshshade.kernels.painted_reflectance import albedo_for_reflectance, model_total_reflectance
from meshshade.light import BeamLight, DirectionalLight
from meshshade.materials import Material
from meshshade.montecarlo import MCOptions, media, simulate
from meshshade.painted import PaintedMaterial
from meshshade.parts import PartedMaterial

igl = pytest.importorskip("igl")


def _sphere(radius=5.0, sub=3):
    V, F = icosphere(radius, sub)
    return Mesh.from_arrays(V, F)


def _interior_points(mesh, n, seed=0, shrink=0.98):
    rng = np.random.default_rng(seed)
    r = np.linalg.norm(mesh.vertices, axis=1).min() * shrink
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return d * (r * rng.random(n) ** (1 / 3))[:, None]


def _bary(P, tri):
    """(k, 3) barycentrics of points ``P`` (k, 3) on triangles ``tri`` (k, 3, 3) (least squares in the plane)."""
    e1, e2, q = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], P - tri[:, 0]
    d11, d12, d22 = (np.einsum("ij,ij->i", a, b) for a, b in ((e1, e1), (e1, e2), (e2, e2)))
    q1, q2 = np.einsum("ij,ij->i", q, e1), np.einsum("ij,ij->i", q, e2)
    det = d11 * d22 - d12 * d12
    v, w = (d22 * q1 - d12 * q2) / det, (d11 * q2 - d12 * q1) / det
    return np.stack([1 - v - w, v, w], axis=1)


# ------------------------------------------------------------------------------------------------ the medium read
def test_albedo_table_error_is_measured_and_small():
    m = Material.preset("skin1")
    lo, hi = 0.05, 0.7
    nodes, alb, start, (c0, inv), err = media.albedo_table(lo, hi, m.eta, m.g)
    assert err <= media.TABLE_TOLERANCE
    # independently: random colours (not the midpoints the table was refined on) against eq. (106) solved
    C = np.random.default_rng(1).uniform(lo, hi, 4000)
    got = np.interp(C, nodes, alb)
    exact = albedo_for_reflectance(C, m.eta, m.g)
    assert np.max(np.abs(got / exact - 1)) <= 1e-6


def test_painted_medium_at_matches_closest_point_colour_and_eq106():
    mesh = _sphere(5.0, 3)
    base = Material.preset("skin1", g=0.5)
    rng = np.random.default_rng(2)
    Rd = model_total_reflectance(base.albedo_prime, base.eta, base.g)
    colour = Rd * rng.uniform(0.5, 1.2, size=(mesh.n_vertices, 3))
    pm = PaintedMaterial(base, colour=colour)
    groups, fields = media.medium_fields(pm, mesh)
    P = _interior_points(mesh, 3000)
    _d, face, closest = igl.point_mesh_squared_distance(P, mesh.vertices, mesh.faces)
    bary = _bary(closest, mesh.vertices[mesh.faces[face]])
    ref_colour = pm.colour_at(face, mesh.faces, bary)
    for (_key, chans), fld in zip(groups, fields):
        c = chans[0]
        a_ref = albedo_for_reflectance(ref_colour[:, c], base.eta, base.g)
        st_p, g = base.sigma_t_prime[c], base.g
        ss = a_ref * st_p / (1 - g)
        st_ref = ss + (1 - a_ref) * st_p
        got = media.medium_at_points(fld, P)
        np.testing.assert_allclose(got[:, 1], ss / st_ref, rtol=2e-6)
        np.testing.assert_allclose(got[:, 0], st_ref, rtol=2e-6)
        assert np.all(got[:, 0] <= fld.majorant)
        assert np.all(got[:, 2] == g)


def test_painted_image_medium_matches_colour_at():
    V, F = uv_sphere(5.0, 16, 32)
    mesh = Mesh.from_arrays(V, F)
    uv = spherical_uv(mesh.vertices, mesh.faces)
    base = Material.preset("marble")
    Rd = model_total_reflectance(base.albedo_prime, base.eta, base.g)
    image = Rd * np.random.default_rng(3).uniform(0.6, 1.1, size=(8, 16, 3))
    pm = PaintedMaterial(base, image=image, uv=uv)
    groups, fields = media.medium_fields(pm, mesh)
    P = _interior_points(mesh, 2000, seed=4, shrink=0.95)
    _d, face, closest = igl.point_mesh_squared_distance(P, mesh.vertices, mesh.faces)
    bary = _bary(closest, mesh.vertices[mesh.faces[face]])
    ref = pm.colour_at(face, mesh.faces, bary)
    for (_key, chans), fld in zip(groups, fields):
        a_ref = albedo_for_reflectance(ref[:, chans[0]], base.eta, base.g)
        got = media.medium_at_points(fld, P)
        # g = 0: sigma_t is sigma_t' everywhere, the albedo is alpha'
        assert fld.constant and np.all(got[:, 0] == fld.majorant)
        np.testing.assert_allclose(got[:, 1], a_ref, rtol=2e-6)


def test_painted_radius_map_scales_sigma_t_at_the_closest_point():
    # eq. (132): sigma_t' is the base's over the radius map's factor at the closest surface point (per vertex and
    # as an image over the UVs, read as colour_at reads the colour); g = 0.5 so that sigma_t != sigma_t'
    V, F = uv_sphere(5.0, 16, 32)
    mesh = Mesh.from_arrays(V, F)
    uv = spherical_uv(mesh.vertices, mesh.faces)
    base = Material.preset("skin1", g=0.5)
    rng = np.random.default_rng(8)
    colour = model_total_reflectance(base.albedo_prime, base.eta, base.g) * rng.uniform(0.7, 1.1, (mesh.n_vertices, 3))
    P = _interior_points(mesh, 2000, seed=9, shrink=0.95)
    _d, face, closest = igl.point_mesh_squared_distance(P, mesh.vertices, mesh.faces)
    bary = _bary(closest, mesh.vertices[mesh.faces[face]])
    per_vertex, image = rng.uniform(0.4, 2.5, mesh.n_vertices), rng.uniform(0.4, 2.5, (8, 16, 3))
    for pm, least in ((PaintedMaterial(base, colour=colour, radius=per_vertex), np.full(3, per_vertex.min())),
                      (PaintedMaterial(base, radius_image=image, uv=uv), image.min(axis=(0, 1)))):
        groups, fields = media.medium_fields(pm, mesh)
        st_p = pm.sigma_t_prime_at(face, mesh.faces, bary)
        a_ref = albedo_for_reflectance(pm.colour_at(face, mesh.faces, bary), base.eta, base.g)
        for (_key, chans), fld in zip(groups, fields):
            c = chans[0]
            ss = a_ref[:, c] * st_p[:, c] / (1 - base.g)
            st_ref = ss + (1 - a_ref[:, c]) * st_p[:, c]
            got = media.medium_at_points(fld, P)
            assert not fld.constant
            np.testing.assert_allclose(got[:, 0], st_ref, rtol=2e-6)
            np.testing.assert_allclose(got[:, 1], ss / st_ref, rtol=2e-6)
            # a majorant, and no larger than any point of this paint could need: sigma_t = sigma_t' (1 + alpha' g /
            # (1 - g)) <= sigma_t' / (1 - g) at the map's least factor
            assert np.all(got[:, 0] <= fld.majorant)
            assert fld.majorant <= base.sigma_t_prime[c] / least[c] / (1 - base.g) * (1 + 1e-12)


@pytest.mark.slow
def test_a_constant_radius_map_walks_as_the_scaled_material():
    """g = 0, the mean free path 1.5x everywhere: delta tracking at the majorant sigma_t' / 1.5, every collision
    real; within 4 standard errors of the homogeneous walk in that medium. (Statistical, 60-70 s on 2 cores: the
    painted walk reads the medium at each collision's closest surface point. The radius map's lookup stays in CI:
    test_painted_radius_map_scales_sigma_t_at_the_closest_point.)"""
    mesh = _sphere(5.0, 3)
    m = Material.preset("skin1")
    scaled = Material(m.sigma_s_prime / 1.5, m.sigma_a / 1.5, m.eta, m.g)
    p = simulate(mesh, PaintedMaterial(m, radius=np.full(mesh.n_vertices, 1.5)), _light(),
                 MCOptions(photons=20_000, seed=4))
    h = simulate(mesh, scaled, _light(), MCOptions(photons=20_000, seed=5))
    assert p.null_collisions == 0
    _close(h, p)
    base = simulate(mesh, m, _light(), MCOptions(photons=20_000, seed=5))
    with pytest.raises(AssertionError):        # the walk does see the scaled path: the base's medium differs
        _close(base, p)


def _core_sphere(R=5.0, r=2.5, sub=4):
    Vo, Fo = icosphere(R, sub)
    Vi, Fi = icosphere(r, sub)
    V = np.concatenate([Vo, Vi])
    F = np.concatenate([Fo, Fi + Vo.shape[0]])
    part = np.concatenate([np.zeros(len(Fo), np.int64), np.ones(len(Fi), np.int64)])
    return Mesh.from_arrays(V, F), part


def test_parts_medium_at_matches_part_at_through_the_grid_and_past_it():
    mesh, part = _core_sphere(5.0, 2.5, 3)
    shell = Material(np.array([1.0, 1.0, 1.0]), np.array([0.01, 0.01, 0.01]), 1.0, 0.0, "shell")
    core = Material(np.array([0.5, 0.5, 0.5]), np.array([2.0, 2.0, 2.0]), 1.0, 0.3, "core")
    pm = PartedMaterial([shell, core], part, ["shell", "core"])
    groups, fields = media.medium_fields(pm, mesh, part == 0)   # the core's faces have the medium on both sides
    fld = fields[0]
    assert 0.3 < fld.grid_fraction < 1.0           # a grid was built, and it leaves the interfaces to the windings
    rng = np.random.default_rng(7)
    near = rng.normal(size=(2000, 3))              # points next to the core's surface: the winding numbers decide
    near *= (2.5 + rng.uniform(-0.05, 0.05, (2000, 1))) / np.linalg.norm(near, axis=1, keepdims=True)
    P = np.concatenate([_interior_points(mesh, 4000, seed=5), near])
    owner = pm.part_at(mesh.vertices, mesh.faces, P)
    assert 0 < np.count_nonzero(owner == 1) < P.shape[0] and np.all(owner >= 0)
    got = media.medium_at_points(fld, P)
    st = np.array([float(m.medium.sigma_s[0] + m.medium.sigma_a[0]) for m in (shell, core)])
    np.testing.assert_array_equal(got[:, 2], np.where(owner == 1, 0.3, 0.0))
    np.testing.assert_array_equal(got[:, 0], st[owner])


# ------------------------------------------------------------------------------------------------ whole walks
def _light():
    return DirectionalLight((0.3, -0.2, -1.0), 1.0)


def _close(a, b, k=4.0):
    """|a - b| within k combined standard errors (totals of two independent runs)."""
    for key in ("diffuse_reflectance", "transmittance", "absorbed"):
        se = np.sqrt(a.totals[key + "_stderr"] ** 2 + b.totals[key + "_stderr"] ** 2)
        assert np.all(np.abs(a.totals[key] - b.totals[key]) <= k * se + 1e-12), (key, a.totals[key], b.totals[key],
                                                                                se)


def test_painted_preset_reflectance_is_the_preset_g0():
    """g = 0: the same random numbers as the homogeneous walk (sigma_t = sigma_t', no null collision)."""
    mesh = _sphere(5.0, 3)
    m = Material.preset("skin1")
    Rd = model_total_reflectance(m.albedo_prime, m.eta, m.g)
    pm = PaintedMaterial(m, colour=np.tile(Rd, (mesh.n_vertices, 1)))
    opt = MCOptions(photons=20_000, seed=3)
    h = simulate(mesh, m, _light(), opt)
    p = simulate(mesh, pm, _light(), opt)
    assert p.null_collisions == 0
    # the table's albedo is eq. (106)'s solution, within TABLE_TOLERANCE of the preset's: the weights differ by
    # at most that much per collision
    np.testing.assert_allclose(p.radiance, h.radiance, rtol=1e-4, atol=1e-9 * h.radiance.max())
    np.testing.assert_allclose(p.totals["absorbed"], h.totals["absorbed"], rtol=1e-4)


def test_painted_preset_reflectance_is_the_preset_delta_tracking():
    """g = 0.8: sigma_t = sigma_t' (1 + alpha' g / (1 - g)) is tracked with a majorant (statistical check; a
    coarser sphere and fewer photons: every collision of this walk searches the closest point)."""
    mesh = _sphere(5.0, 2)
    m = Material.preset("skin1", g=0.8)
    Rd = model_total_reflectance(m.albedo_prime, m.eta, m.g)
    rng = np.random.default_rng(0)   # a paint that varies a little (the table and its kinks are read)
    colour = np.tile(Rd, (mesh.n_vertices, 1))
    pm = PaintedMaterial(m, colour=colour * (1 + 1e-9 * rng.random(colour.shape)))
    h = simulate(mesh, m, _light(), MCOptions(photons=6_000, seed=1))
    p = simulate(mesh, pm, _light(), MCOptions(photons=6_000, seed=2))
    _close(h, p)


def test_parts_of_one_material_are_the_material():
    mesh = _sphere(5.0, 3)
    m = Material.preset("skin1")
    pm = PartedMaterial([m], np.zeros(mesh.n_faces, dtype=np.int64))
    opt = MCOptions(photons=20_000, seed=3)
    h = simulate(mesh, m, _light(), opt)
    p = simulate(mesh, pm, _light(), opt)
    assert p.null_collisions == 0
    np.testing.assert_array_equal(p.radiance, h.radiance)
    np.testing.assert_array_equal(p.totals["absorbed"], h.totals["absorbed"])


def test_null_collisions_leave_the_medium_unchanged(monkeypatch):
    """A majorant three times sigma_t: two of three tentative collisions are null; the result is the same medium."""
    mesh = _sphere(5.0, 3)
    m = Material.preset("skin1")
    monkeypatch.setattr(media, "MAJORANT_FACTOR", 3.0)
    pm = PartedMaterial([m, m], np.zeros(mesh.n_faces, dtype=np.int64), ["a", "b"])
    p = simulate(mesh, pm, _light(), MCOptions(photons=20_000, seed=5))
    h = simulate(mesh, m, _light(), MCOptions(photons=20_000, seed=6))
    assert p.null_collisions > 1.5 * p.events
    _close(h, p)


# ------------------------------------------------------------------------------------------------ independent walk
def _numpy_core_sphere_walk(n, R, r, shell, core, seed):
    """Fractions (reflected through z > 0, transmitted through z <= 0, absorbed) and their standard errors of
    an analog random walk in a sphere of radius R with a concentric core of radius r, eta = 1 everywhere, a
    pencil beam entering at the north pole along -z. shell, core: (sigma_s, sigma_a) 1/mm, isotropic
    scattering. Regular tracking: an optical depth -ln(u) spent region by region across the exact spheres."""
    rng = np.random.default_rng(seed)
    p = np.tile([0.0, 0.0, R * (1 - 1e-12)], (n, 1))
    d = np.tile([0.0, 0.0, -1.0], (n, 1))
    out = np.zeros(n, dtype=np.int8)          # 0 alive, 1 reflected, 2 transmitted, 3 absorbed
    tau = -np.log1p(-rng.random(n))
    st = np.array([shell[0] + shell[1], core[0] + core[1]])
    alb = np.array([shell[0] / st[0], core[0] / st[1]])

    def sphere_exit(p, d, rad):        # distance along d to leave the sphere |x| = rad from inside
        b = np.einsum("ij,ij->i", p, d)
        c = np.einsum("ij,ij->i", p, p) - rad * rad
        return -b + np.sqrt(np.maximum(b * b - c, 0.0))

    def sphere_enter(p, d, rad):       # distance to enter the sphere from outside (inf: misses)
        b = np.einsum("ij,ij->i", p, d)
        c = np.einsum("ij,ij->i", p, p) - rad * rad
        disc = b * b - c
        t = -b - np.sqrt(np.maximum(disc, 0.0))
        return np.where((disc > 0) & (t > 0), t, np.inf)

    for _ in range(100_000):
        live = np.flatnonzero(out == 0)
        if live.size == 0:
            break
        P, D = p[live], d[live]
        in_core = np.einsum("ij,ij->i", P, P) < r * r
        reg = in_core.astype(np.int64)
        t_out = np.where(in_core, sphere_exit(P, D, r), np.minimum(sphere_exit(P, D, R), sphere_enter(P, D, r)))
        s = tau[live] / st[reg]
        collide = s < t_out
        step = np.where(collide, s, t_out)
        P = P + step[:, None] * D
        # crossing: spend the optical depth, nudge across the interface
        tau[live] = np.where(collide, 0.0, tau[live] - st[reg] * t_out)
        P = np.where(collide[:, None], P, P + 1e-9 * D)
        leave = ~collide & (np.einsum("ij,ij->i", P, P) >= R * R)
        out[live[leave]] = np.where(P[leave, 2] > 0, 1, 2)
        col = np.flatnonzero(collide)
        absorbed = rng.random(col.size) >= alb[reg[col]]
        out[live[col[absorbed]]] = 3
        sc = col[~absorbed]
        nd = rng.normal(size=(sc.size, 3))
        D[sc] = nd / np.linalg.norm(nd, axis=1, keepdims=True)
        tau[live[collide]] = -np.log1p(-rng.random(int(collide.sum())))
        p[live], d[live] = P, D
    frac = np.array([np.mean(out == k) for k in (1, 2, 3)])
    return frac, np.sqrt(frac * (1 - frac) / n)


@pytest.mark.slow
def test_core_sphere_against_an_independent_numpy_walk():
    R, r = 5.0, 2.5
    shell, core = (1.0, 0.02), (0.3, 1.5)      # the core absorbs, and its sigma_t is 1.76x the shell's
    mesh, part = _core_sphere(R, r, 4)
    pm = PartedMaterial([Material(np.full(3, shell[0]), np.full(3, shell[1]), 1.0, 0.0, "shell"),
                         Material(np.full(3, core[0]), np.full(3, core[1]), 1.0, 0.0, "core")], part,
                        ["shell", "core"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MeshDefectWarning)      # the core's faces are index-matched (said once)
        mc = simulate(mesh, pm, BeamLight((0.011, 0.007, 2 * R), (0, 0, -1)), MCOptions(photons=40_000, seed=9))
    assert mc.null_collisions > 0
    ref, ref_se = _numpy_core_sphere_walk(40_000, R, r, shell, core, seed=11)
    got = np.array([mc.totals[k][0] for k in ("diffuse_reflectance", "transmittance", "absorbed")])
    se = np.array([mc.totals[k + "_stderr"][0] for k in ("diffuse_reflectance", "transmittance", "absorbed")])
    # the icospheres (subdivision 4) lie within 6e-4 R of the exact spheres: a systematic allowance of 2e-3
    assert np.all(np.abs(got - ref) <= 4 * np.sqrt(se ** 2 + ref_se ** 2) + 2e-3), (got, ref, se, ref_se)
