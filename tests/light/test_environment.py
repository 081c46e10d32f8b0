"""Environment lights (issue 43): the map's directions, its importance sampling and the quadrature of what a
surface point receives.

Independent routes for every expected value:

* directions of pixels: Cycles' ``direction_to_equirectangular`` (intern/cycles/kernel/camera/projection.h:
  u = 0.5 - atan2(y, x) / 2 pi, v = 1 - acos(z) / pi, v = 0 at the image's bottom row) applied by hand to the
  directions of Blender's world, and the Y-up -> Blender axis conversion of Blender's glTF and OBJ importers
  ((x, y, z) -> (x, -z, y)); Blender's Mapping node (type Point) rotates the lookup vector by R_z(angle);
* integrals: closed forms (a uniform sky gives pi L on any unoccluded plane; a sky of latitude bands gives
  sum_r L_r pi (sin^2 theta_r+1 - sin^2 theta_r) on a plane facing the zenith) and, for a tilted plane under an
  arbitrary map, a midpoint quadrature of cos+ over every pixel written here from the definition (the map is
  piecewise constant over pixels) with this file's own pixel geometry;
* Fresnel: the unpolarised Fresnel formulae (Born & Wolf 1.5.2) evaluated with mpmath.

Statistical checks compare the mean over many independent points (each its own randomised rule) with the exact
value, within 5 standard errors of that mean measured from the points' spread.
"""
from __future__ import annotations

import math

import mpmath as mp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from meshshade.errors import LightError
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.io import write_exr
from meshshade.light import EnvironmentLight, entry_samples, parse_light_spec
from meshshade.light.environment import environment_from_rgb, map_sampler
from meshshade.light.incidence import light_incidence
from meshshade.light.sky_loops import cosine_direction, env_direction, env_pixel, pack_sky
from meshshade.raycast import make_scene

ETA = 1.3


# ------------------------------------------------------------------------------------------------ helpers
def blender_uv(b):
    """(u, row fraction from the top) of a Blender-frame unit direction by Cycles' formula."""
    u = (0.5 - math.atan2(b[1], b[0]) / (2 * math.pi)) % 1.0
    v = 1.0 - math.acos(max(-1.0, min(1.0, b[2]))) / math.pi
    return u, 1.0 - v


def yup_to_blender(w):
    x, y, z = w
    return (x, -z, y)


def rot_z(b, deg):
    a = math.radians(deg)
    return (math.cos(a) * b[0] - math.sin(a) * b[1], math.sin(a) * b[0] + math.cos(a) * b[1], b[2])


def far_scene(normal):
    """A tiny triangle 100 mm behind the point at the origin: nothing in the normal's hemisphere is occluded."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    t = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
    t /= np.linalg.norm(t)
    c = -100.0 * n
    V = np.array([c, c + t, c + np.cross(n, t)])
    return make_scene(V, np.array([[0, 1, 2]]))


def fresnel_t_mp(mu, eta):
    mu = mp.mpf(mu)
    ct = mp.sqrt(1 - (1 - mu * mu) / eta ** 2)
    rs = (mu - eta * ct) / (mu + eta * ct)
    rp = (eta * mu - ct) / (eta * mu + ct)
    return 1 - (rs * rs + rp * rp) / 2


def entering_fraction(eta=ETA):
    """(1/pi) integral over the hemisphere of cos F_t(cos) d omega = 2 integral_0^1 mu F_t(mu) d mu."""
    return float(2 * mp.quad(lambda mu: mu * fresnel_t_mp(mu, mp.mpf(eta)), [0, 1]))


def quadrature_many(light, normals, directions=None, seed_points=200):
    """Estimates of the incident irradiance at ``seed_points`` copies of a point (each its own random shifts)."""
    n = np.asarray(normals, float)
    N = np.broadcast_to(n / np.linalg.norm(n), (seed_points, 3)).copy()
    P = np.zeros((seed_points, 3))
    inc = light_incidence(light, P, N, np.ones(seed_points), far_scene(n), ETA, directions=directions)
    return inc.moments[:, 1], inc.moments[:, 0], inc


def pixel_cos_integrals(H, W, n, up="y", rotation=0.0, sub=48):
    """(H, W) integral over each pixel of max(0, n . w) d omega, by a midpoint rule in (cos theta, phi) with this
    file's own geometry (row r spans theta in [r pi/H, (r+1) pi/H] from the map's zenith, column c spans u in
    [c/W, (c+1)/W] with phi = pi - 2 pi u in the Blender frame)."""
    out = np.zeros((H, W))
    a = (np.arange(sub) + 0.5) / sub
    for r in range(H):
        c0, c1 = math.cos(math.pi * r / H), math.cos(math.pi * (r + 1) / H)
        ct = c0 + a * (c1 - c0)
        stt = np.sqrt(1 - ct * ct)
        for c in range(W):
            phi = math.pi - 2 * math.pi * (c + a) / W
            T = np.stack([np.outer(stt, np.cos(phi)), np.outer(stt, np.sin(phi)), np.outer(ct, np.ones(sub))], -1)
            T = T.reshape(-1, 3)
            ang = -math.radians(rotation)      # lookup t = Rz(rot) b  =>  b = Rz(-rot) t
            b = np.stack([math.cos(ang) * T[:, 0] - math.sin(ang) * T[:, 1],
                          math.sin(ang) * T[:, 0] + math.cos(ang) * T[:, 1], T[:, 2]], 1)
            w = b if up == "z" else np.stack([b[:, 0], b[:, 2], -b[:, 1]], 1)
            dom = (2 * math.pi / W) * (c0 - c1) / (sub * sub)
            out[r, c] = np.sum(np.clip(w @ n, 0, None)) * dom
    return out


# ------------------------------------------------------------------------------------------------ directions
@pytest.mark.parametrize("up", ["y", "z"])
@pytest.mark.parametrize("rotation", [0.0, 90.0, -37.0])
def test_pixels_follow_cycles_equirectangular_convention(up, rotation, rng):
    Y = rng.random((16, 32)) + 0.1
    s = map_sampler(EnvironmentLight(Y, rotation_deg=rotation, up=up))
    W = rng.normal(size=(400, 3))
    W /= np.linalg.norm(W, axis=1, keepdims=True)
    row, col = s.pixels(W)
    for k, w in enumerate(W):
        b = tuple(w) if up == "z" else yup_to_blender(w)
        u, frac = blender_uv(rot_z(b, rotation))
        assert col[k] == min(int(u * 32), 31) and row[k] == min(int(frac * 16), 15), (w, u, frac)


def test_landmarks_of_the_y_up_convention():
    """The image's centre column looks along +X, u = 0.75 along +Z, u = 0.25 along -Z, the top row is +Y."""
    s = map_sampler(EnvironmentLight(np.ones((4, 8))))
    row, col = s.pixels(np.array([[1.0, 0, 0], [0, 0, 1.0], [0, 0, -1.0], [0, 1.0, 0], [0, -1.0, 0]]))
    assert col[:3].tolist() == [4, 6, 2]
    assert row[3] == 0 and row[4] == 3


def test_samples_land_in_the_pixel_drawn_with_density_proportional_to_radiance(rng):
    Y = rng.random((12, 24)) ** 3 + 1e-3
    s = map_sampler(EnvironmentLight(Y, rotation_deg=20.0))
    n = 400_000
    w = s.sample(rng.random(n), rng.random(n))
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1.0, atol=1e-12)
    row, col = s.pixels(w)
    counts = np.bincount(row * 24 + col, minlength=Y.size)
    ce = np.cos(np.pi * np.arange(13) / 12)
    omega = (2 * np.pi / 24) * (ce[:-1] - ce[1:])               # the pixels' solid angles, by hand
    p = (Y * omega[:, None]).ravel()
    p /= p.sum()
    z = (counts - n * p) / np.sqrt(n * p * (1 - p))
    assert np.abs(z).max() < 5.0
    # the density inside a pixel is uniform in solid angle: p(w) = Y / sum(Y Omega) everywhere
    np.testing.assert_allclose(s.pdf(w), Y[row, col] / np.sum(Y * omega[:, None]), rtol=1e-12)


def test_rows_without_light_are_never_drawn(rng):
    Y = np.zeros((8, 16))
    Y[2, 3] = 5.0
    Y[6, :] = 1.0
    s = map_sampler(EnvironmentLight(Y))
    row, col = s.pixels(s.sample(rng.random(50_000), rng.random(50_000)))
    assert set(zip(row.tolist(), col.tolist())) <= {(2, 3)} | {(6, c) for c in range(16)}


@settings(max_examples=200, deadline=None)
@given(st.floats(0.0, 0.999999), st.floats(0.0, 0.999999), st.sampled_from(["y", "z"]), st.floats(-180, 180))
def test_compiled_twins_match_the_numpy_sampler(x, y, up, rotation):
    Y = np.arange(1.0, 1.0 + 8 * 16).reshape(8, 16) % 7 + 0.5
    Y[3, :] = 0.0
    light = EnvironmentLight(Y, rotation_deg=rotation, up=up)
    s = map_sampler(light)
    params = np.zeros((1, 24))
    sky = pack_sky([light], params)
    w = s.sample(np.array([x]), np.array([y]))[0]
    got = env_direction(params[0], sky.row_cdf, sky.flat_cdf, sky.cos_edges, x, y)
    np.testing.assert_allclose(got, w, atol=1e-12)
    r, c = s.pixels(w[None])
    assert env_pixel(params[0], *w) == r[0] * 16 + c[0]


@settings(max_examples=200, deadline=None)
@given(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1), st.floats(0.0, 0.999999), st.floats(0.0, 0.999999))
def test_cosine_directions_are_unit_and_above_the_normal(a, b, c, x, y):
    n = np.array([a, b, c])
    if np.linalg.norm(n) < 1e-3:
        return
    n /= np.linalg.norm(n)
    w = np.array(cosine_direction(*n, x, y))
    assert abs(np.linalg.norm(w) - 1.0) < 1e-12
    assert w @ n == pytest.approx(math.sqrt(1 - x), abs=1e-9)    # Malley: cos theta = sqrt(1 - x)


# ------------------------------------------------------------------------------------------------ integrals
def test_uniform_sky_gives_pi_L_and_the_fresnel_share_enters():
    L = 0.37
    for normal in ([0, 0, 1.0], [0.3, -0.8, 0.2], [0, -1.0, 0]):
        inc, ent, _ = quadrature_many(EnvironmentLight.uniform(L), normal, directions=64)
        for est, exact in ((inc, math.pi * L), (ent, math.pi * L * entering_fraction())):
            se = est.std(ddof=1) / math.sqrt(est.size)
            assert abs(est.mean() - exact) < 5 * se + 1e-12 * exact, (normal, est.mean(), exact, se)


def test_latitude_bands_on_a_plane_facing_the_zenith():
    H = 8
    bands = np.array([3.0, 1.0, 0.5, 7.0, 0.2, 0.1, 0.0, 2.0])
    light = EnvironmentLight(np.repeat(bands[:, None], 2 * H, axis=1))
    th = np.pi * np.arange(H + 1) / H
    exact = sum(bands[r] * np.pi * (np.sin(th[r + 1]) ** 2 - np.sin(th[r]) ** 2) for r in range(H // 2))
    inc, _, _ = quadrature_many(light, [0, 1.0, 0], directions=64)       # y is up
    se = inc.std(ddof=1) / math.sqrt(inc.size)
    assert abs(inc.mean() - exact) < 5 * se, (inc.mean(), exact, se)


@pytest.mark.parametrize("up,rotation,normal", [("y", 0.0, [0.4, 0.5, -0.3]), ("z", 30.0, [0.1, -0.9, 0.4]),
                                                 ("y", -75.0, [-0.7, -0.2, 0.6])])
def test_tilted_plane_under_an_arbitrary_map(up, rotation, normal, rng):
    H, W = 6, 12
    Y = rng.random((H, W)) ** 2
    Y[1, 4] = 30.0                                              # a small bright source
    n = np.asarray(normal) / np.linalg.norm(normal)
    exact = float(np.sum(Y * pixel_cos_integrals(H, W, n, up, rotation)))
    light = EnvironmentLight(Y, rotation_deg=rotation, up=up)
    inc, _, _ = quadrature_many(light, n, directions=64, seed_points=300)
    se = inc.std(ddof=1) / math.sqrt(inc.size)
    assert abs(inc.mean() - exact) < 5 * se, (inc.mean(), exact, se)
    assert se < 0.01 * exact                                     # and the check has teeth


def test_reported_error_is_the_scatter_between_seeds_and_follows_the_target():
    """The rule's self-reported relative error matches the scatter of two independent runs, and a tighter
    ``error`` buys more directions and a smaller error."""
    Y = np.ones((16, 32))
    Y[4:6, 5:8] = 40.0
    mesh = Mesh.from_arrays(*icosphere(10.0, 3))
    scene = make_scene(mesh.vertices, mesh.faces)
    out = {}
    for err in (0.04, 0.01):
        runs = []
        for seed in (1, 2):
            inc = light_incidence(EnvironmentLight(Y, error=err, seed=seed), mesh.vertices, mesh.vertex_normals,
                                  mesh.vertex_areas, scene, ETA)
            runs.append(inc)
        a, b = runs[0].moments[:, 1], runs[1].moments[:, 1]
        observed = np.sqrt(np.mean(((a - b) / (0.5 * (a + b))) ** 2) / 2.0)
        reported = math.sqrt(np.mean(runs[0].rel_error ** 2))
        assert 0.6 < observed / reported < 1.6, (err, observed, reported)
        assert runs[0].stats["rel_error_rms"] < 1.5 * err
        out[err] = (runs[0].directions, observed)
    assert out[0.01][0] > out[0.04][0] and out[0.01][1] < out[0.04][1]


def test_same_seed_same_samples_other_seed_others():
    mesh = Mesh.from_arrays(*icosphere(10.0, 2))
    args = (mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.vertex_areas)
    Y = np.ones((8, 16))
    Y[2, 2] = 50.0
    a = entry_samples(*args, [EnvironmentLight(Y, seed=3)], eta=ETA)
    b = entry_samples(*args, [EnvironmentLight(Y, seed=3)], eta=ETA)
    c = entry_samples(*args, [EnvironmentLight(Y, seed=4)], eta=ETA)
    np.testing.assert_array_equal(a.power, b.power)
    np.testing.assert_array_equal(a.directions, b.directions)
    assert not np.array_equal(a.power, c.power)


# ------------------------------------------------------------------------------------------------ entry samples
def test_rotation_by_90_degrees_lights_plus_z_of_a_y_up_mesh():
    """A small bright spot at the map's centre (Blender +X) rotated by +90 degrees about the up axis: Blender's
    Mapping sends it to R_z(-90) (1, 0, 0) = (0, -1, 0) in Blender's frame, (0, 0, 1) in a Y-up mesh."""
    Y = np.zeros((32, 64))
    Y[15:17, 31:33] = 1.0                                         # around u = 0.5, the equator
    mesh = Mesh.from_arrays(*icosphere(10.0, 3))
    args = (mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.vertex_areas)
    for rotation, toward in ((0.0, [1.0, 0, 0]), (90.0, [0, 0, 1.0]), (-90.0, [0, 0, -1.0])):
        s = entry_samples(*args, [EnvironmentLight(Y, rotation_deg=rotation)], eta=ETA)
        mean_normal = np.sum(s.normals * s.power[:, None], axis=0)
        mean_normal /= np.linalg.norm(mean_normal)
        assert mean_normal @ np.array(toward) > 0.99, (rotation, mean_normal)
        # and its light travels away from that side, into the mesh
        d = np.sum(s.directions * s.power[:, None], axis=0)
        assert (d / np.linalg.norm(d)) @ np.array(toward) < -0.99


def test_aggregated_samples_keep_power_depth_and_drift(rng):
    """Up to four samples per vertex: their entering power is the vertex's, and the power-weighted mean of their
    refracted directions' normal and tangential parts is the fan's (each row's refraction by Snell, here)."""
    Y = rng.random((8, 16)) + 0.05
    Y[2, 3] = 60.0
    mesh = Mesh.from_arrays(*icosphere(10.0, 2))
    scene = make_scene(mesh.vertices, mesh.faces)
    light = EnvironmentLight(Y, max_directions=64)
    inc = light_incidence(light, mesh.vertices, mesh.vertex_normals, mesh.vertex_areas, scene, ETA, rows=True)
    from meshshade.light.incidence import aggregate_samples
    pt, power, d, cos = aggregate_samples(inc, mesh.vertex_normals, ETA)
    n = mesh.n_vertices
    np.testing.assert_allclose(np.bincount(pt, power, n), np.bincount(inc.point, inc.entering, n), rtol=1e-12)
    assert np.all(np.bincount(pt, minlength=n) <= 4)

    def refract(dirs, normals):
        ci = -np.einsum("ij,ij->i", dirs, normals)
        ct = np.sqrt(1 - (1 - ci ** 2) / ETA ** 2)
        return dirs / ETA + (ci / ETA - ct)[:, None] * normals

    def weighted_mean(p, w, q):
        return np.stack([np.bincount(p, w * q[:, k], n) for k in range(3)], 1)

    agg = weighted_mean(pt, power, refract(d, mesh.vertex_normals[pt]))
    rows = weighted_mean(inc.point, inc.entering, refract(inc.direction, mesh.vertex_normals[inc.point]))
    np.testing.assert_allclose(agg, rows, atol=1e-9 * np.abs(rows).max())
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(-np.einsum("ij,ij->i", d, mesh.vertex_normals[pt]), cos, atol=1e-12)


def test_a_sky_that_the_object_hides_everywhere_is_one_line_error():
    """A ball inside a closed box (the box's vertices take no light): every direction from the ball is shadowed."""
    ball_v, ball_f = icosphere(5.0, 2)
    box_v = np.array([[x, y, z] for x in (-20, 20) for y in (-20, 20) for z in (-20, 20)], float)
    box_f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                      [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    V = np.vstack([ball_v, box_v])
    F = np.vstack([ball_f, box_f + len(ball_v)])
    N = np.vstack([ball_v / np.linalg.norm(ball_v, axis=1, keepdims=True), np.tile([0, 0, 1.0], (8, 1))])
    A = np.concatenate([np.full(len(ball_v), 1.0), np.zeros(8)])
    with pytest.raises(LightError, match=r"uniform light 0 .* shadowed from every direction"):
        entry_samples(V, F, N, A, [EnvironmentLight.uniform(1.0)], eta=ETA)
    box_open = F[:-2]                                             # one wall gone: light gets in
    s = entry_samples(V, box_open, N, A, [EnvironmentLight.uniform(1.0)], eta=ETA)
    assert len(s) > 0


# ------------------------------------------------------------------------------------------------ files
def _exr(tmp_path, name, img):
    p = tmp_path / name
    write_exr(p, np.asarray(img, np.float32))
    return p


def _raw_exr(path, img):
    """An EXR written by OpenImageIO as it is (meshshade's writer refuses NaN: a map made elsewhere may hold it)."""
    import OpenImageIO as oiio
    img = np.ascontiguousarray(img, np.float32)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(img.shape[1], img.shape[0], img.shape[2], "float"))
    assert out.write_image(img)
    out.close()
    return path


def test_spec_reads_the_map_strength_rotation_and_up(tmp_path):
    img = np.zeros((8, 16, 3))
    img[..., 0], img[..., 1], img[..., 2] = 1.0, 2.0, 4.0
    p = _exr(tmp_path, "sky.exr", img)
    with pytest.warns(UserWarning, match="coloured"):
        light = parse_light_spec(f"env:{p}:2.5:45:z")
    assert light.strength == 2.5 and light.rotation_deg == 45.0 and light.up == "z" and light.path == str(p)
    np.testing.assert_allclose(light.radiance, 0.2126 + 0.7152 * 2 + 0.0722 * 4, rtol=1e-6)   # Rec. 709 by hand
    grey = _exr(tmp_path, "grey.exr", np.full((8, 16, 3), 0.5))
    d = parse_light_spec(f"env:{grey}")
    assert d.strength == 1.0 and d.rotation_deg == 0.0 and d.up == "y"
    colon = tmp_path / "a:b"
    colon.mkdir()
    c = _exr(colon, "sky.exr", np.full((8, 16, 3), 0.5))
    assert parse_light_spec(f"env:{c}:3").path == str(c)


@pytest.mark.parametrize("kind,needle", [
    ("missing", "does not exist"), ("folder", "is a folder"), ("garbage", "cannot be read"),
    ("square", "twice as wide"), ("nan", "NaN or infinite"), ("negative", "negative values"),
    ("black", "black"), ("two", "2 channels")])
def test_bad_maps_are_one_line_errors(tmp_path, kind, needle):
    img = np.full((8, 16, 3), 0.5, np.float32)
    if kind == "missing":
        p = tmp_path / "nope.exr"
    elif kind == "folder":
        p = tmp_path / "dir.exr"
        p.mkdir()
    elif kind == "garbage":
        p = tmp_path / "g.exr"
        p.write_bytes(b"not an image")
    elif kind == "square":
        p = _exr(tmp_path, "sq.exr", np.full((8, 8, 3), 0.5))
    elif kind == "two":
        p = _raw_exr(tmp_path / "two.exr", np.ones((8, 16, 2)))
    else:
        img[3, 4, 1] = {"nan": np.nan, "negative": -1.0, "black": 0.0}[kind]
        if kind == "black":
            img[:] = 0.0
        p = _raw_exr(tmp_path / f"{kind}.exr", img)
    with pytest.raises(LightError) as exc:
        parse_light_spec(f"env:{p}")
    msg = str(exc.value)
    assert needle in msg and "\n" not in msg and str(p.name) in msg


@pytest.mark.parametrize("spec,needle", [
    ("uniform:-1", "uniform radiance must be > 0"), ("uniform:nan", "must be finite"), ("uniform:1:2", "look like"),
    ("env:", "look like"), ("uniform:abc", "must be a number")])
def test_bad_specs(spec, needle):
    with pytest.raises(LightError, match=needle):
        parse_light_spec(spec)


def test_a_bad_field_after_an_existing_map_says_which(tmp_path):
    p = _exr(tmp_path, "sky.exr", np.full((8, 16, 3), 0.5))
    with pytest.raises(LightError, match="strength, rotation"):
        parse_light_spec(f"env:{p}:2x")


def test_from_rgb_of_a_grey_map_does_not_warn(recwarn):
    environment_from_rgb(np.full((4, 8, 3), 0.25))
    assert not [w for w in recwarn if "coloured" in str(w.message)]


def test_the_convex_rule_skips_rays_and_changes_nothing():
    """On a convex mesh the shadow rays above one of a vertex's faces are skipped; the result is the one with every
    ray cast. On a torus (not convex) nothing may be skipped: its far side shadows its inner ring."""
    from meshshade.geometry.procedural import torus
    from meshshade.light.incidence import SupportingPlanes
    Y = np.ones((8, 16))
    Y[2, 6] = 80.0
    light = EnvironmentLight(Y, rotation_deg=10.0)
    for mesh, convex in ((Mesh.from_arrays(*icosphere(10.0, 2)), True),
                         (Mesh.from_arrays(*torus(10.0, 4.0, 32, 16)), False)):
        scene = make_scene(mesh.vertices, mesh.faces)
        args = (light, mesh.vertices, mesh.vertex_normals, mesh.vertex_areas, scene, ETA)
        planes = SupportingPlanes(mesh.vertices, mesh.faces)
        assert planes.convex == convex
        ruled = light_incidence(*args, directions=64, planes=planes, vertex_ids=np.arange(mesh.n_vertices))
        every = light_incidence(*args, directions=64)
        assert (ruled.stats["rays_skipped"] > 0) == convex and every.stats["rays_skipped"] == 0
        np.testing.assert_array_equal(ruled.moments, every.moments)
