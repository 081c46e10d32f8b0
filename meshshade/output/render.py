"""Images of a baked mesh: camera, primary rays (Embree), image formation. Returns arrays, writes nothing.

Radiance toward the camera (the convention meshshade uses)
---------------------------------------------------------
The bake gives the radiant exitance M [W/mm^2] leaving the surface (Jensen's R_d already accounts for the
boundary). It is spread over the outgoing hemisphere with the exit Fresnel factor of Jensen et al. 2001's
S_d (``F_t(eta, omega_o) / pi``), normalised so that the hemisphere integral gives back M:

    L(omega_o) = F_t(eta, cos_o) M / (pi C(eta)),     C(eta) = 2 int_0^1 F_t(eta, mu) mu dmu

(``F_t = 1 - F_r`` for light leaving into air, evaluated with the outside angle; by reciprocity the same as the
entry transmittance). int L cos dω = M exactly. C(1.3) = 0.939, C(1.5) = 0.908. L is in W/(mm^2 sr).

Per-vertex vs per-pixel
-----------------------
* default: M is interpolated with the hit's barycentrics from the per-vertex bake (cheap: one ray per sample).
  Near a pencil beam the peak is smeared over the entry triangle's fan.
* ``per_pixel``: the near field of the kernel (point entry samples, i.e. beams, within 8-16 mean edge lengths)
  is gathered at each sample's own surface point, the smooth far field is interpolated from the bake
  (:class:`PixelGather`). Near distances are the chord corrected to an arc with the source's normal curvature
  in that direction, ``s = 2 asin(|k_n| c / 2) / |k_n|`` (exact on a sphere). Directional and point lights
  (vertex samples) gain nothing from it and render as per-vertex.
"""
from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
from scipy.spatial import cKDTree

from meshshade.errors import MeshshadeError
from meshshade.kernels.fresnel import fresnel_transmittance_entry, refract_in
from meshshade.output.tonemap import srgb_encode, tonemap_linear
from meshshade.raycast import make_scene
from meshshade.surface.gather import gather
from meshshade.surface.source_factors import drift_angles, near_field_factors, refracted_drift
from meshshade.surface.pair_kernel import PairKernel, source_frames
from meshshade.surface.patch_average import source_patch_radius


# ------------------------------------------------------------------------------------------------ camera
@dataclass(frozen=True)
class Camera:
    """Pinhole (``perspective``, vertical ``fov_deg``) or ``orthographic`` (vertical extent ``ortho_height`` mm)."""

    kind: str
    eye: tuple
    target: tuple
    up: tuple = (0.0, 1.0, 0.0)
    fov_deg: float = 30.0
    ortho_height: float = 1.0

    def __post_init__(self):
        if self.kind not in ("perspective", "orthographic"):
            raise MeshshadeError(f"camera kind must be perspective or orthographic, got {self.kind!r}")
        for name in ("eye", "target", "up"):
            object.__setattr__(self, name, _camera_vec3(getattr(self, name), f"camera {name}"))
        with np.errstate(over="ignore", invalid="ignore"):
            f = np.subtract(self.target, self.eye)
        if not np.any(f != 0.0):
            raise MeshshadeError(f"camera eye and target must differ, both are {_fmt3(self.eye)}")
        if not np.all(np.isfinite(f)):
            raise MeshshadeError(f"camera eye {_fmt3(self.eye)} and target {_fmt3(self.target)} are too far apart")
        up = np.asarray(self.up)
        if not np.any(up != 0.0):
            raise MeshshadeError("camera up vector must be non-zero, got (0, 0, 0)")
        f, up = f / np.max(np.abs(f)), up / np.max(np.abs(up))   # scaled first: no overflow in the norms
        if np.linalg.norm(np.cross(f, up)) < 1e-9 * np.linalg.norm(f) * np.linalg.norm(up):
            raise MeshshadeError(f"camera up vector {_fmt3(self.up)} is parallel to the view direction "
                                 f"{_fmt3(f / np.linalg.norm(f))}")
        if self.kind == "perspective":
            fov = _camera_number(self.fov_deg, "camera fov")
            if not 0.0 < fov < 180.0:
                raise MeshshadeError(f"camera fov must lie in (0, 180) degrees, got {self.fov_deg!r}")
            object.__setattr__(self, "fov_deg", fov)
        else:
            height = _camera_number(self.ortho_height, "orthographic camera height")
            if not 0.0 < height < math.inf:
                raise MeshshadeError(f"orthographic camera height must be finite and > 0 mm, got "
                                     f"{self.ortho_height!r}")
            object.__setattr__(self, "ortho_height", height)

    def basis(self):
        """(forward, right, up) unit vectors."""
        f = np.asarray(self.target, float) - np.asarray(self.eye, float)
        f /= np.linalg.norm(f)
        r = np.cross(f, np.asarray(self.up, float))
        r /= np.linalg.norm(r)
        return f, r, np.cross(r, f)

    def rays(self, x_ndc, y_ndc, aspect):
        """Ray origins and unit directions for normalised image coordinates in [-1, 1] (y up)."""
        f, r, u = self.basis()
        eye = np.asarray(self.eye, float)
        x = np.asarray(x_ndc, float)[..., None]
        y = np.asarray(y_ndc, float)[..., None]
        if self.kind == "perspective":
            h = np.tan(np.radians(self.fov_deg) / 2)
            d = f + x * h * aspect * r + y * h * u
            d /= np.linalg.norm(d, axis=-1, keepdims=True)
            return np.broadcast_to(eye, d.shape).copy(), d
        half = self.ortho_height / 2
        o = eye + x * half * aspect * r + y * half * u
        return o, np.broadcast_to(f, o.shape).copy()

    def describe(self) -> str:
        e, t, u = (",".join(f"{v:.6g}" for v in a) for a in (self.eye, self.target, self.up))
        extra = f"fov {self.fov_deg:g} deg" if self.kind == "perspective" else f"height {self.ortho_height:.6g} mm"
        return f"{self.kind} eye {e} target {t} up {u} {extra}"


def _fmt3(v) -> str:
    return "(" + ", ".join(f"{0.0 + float(x):.6g}" for x in v) + ")"


def _camera_number(value, what: str) -> float:
    try:
        return float(value) if not isinstance(value, (bool, str)) else math.nan
    except (TypeError, ValueError):
        raise MeshshadeError(f"{what} must be a number, got {value!r}") from None


def _camera_vec3(value, what: str) -> tuple:
    """3 finite floats; MeshshadeError naming ``what`` otherwise."""
    try:
        v = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise MeshshadeError(f"{what} must be 3 numbers x,y,z, got {value!r}") from None
    if v.size != 3:
        raise MeshshadeError(f"{what} must be 3 numbers x,y,z, got {value!r}")
    if not np.all(np.isfinite(v)):
        raise MeshshadeError(f"{what} must be finite, got {_fmt3(v)}")
    return tuple(float(x) for x in v)


def auto_camera(mesh, view_dir=(0.0, 0.0, -1.0), *, kind="perspective", fov_deg=30.0, margin=1.08) -> Camera:
    """A camera looking along ``view_dir`` (3 finite numbers, not all 0) at the bounding-box centre that frames the
    whole mesh (``margin`` > 0 times its bounding sphere)."""
    d = np.array(_camera_vec3(view_dir, "camera auto view direction dx,dy,dz"))
    if not np.any(d != 0.0):
        raise MeshshadeError("camera auto view direction dx,dy,dz must be non-zero, got (0, 0, 0)")
    d /= np.max(np.abs(d))
    d /= np.linalg.norm(d)
    margin = _camera_number(margin, "camera margin")
    if not 0.0 < margin < math.inf:
        raise MeshshadeError(f"camera margin must be finite and > 0, got {margin!r}")
    lo, hi = mesh.bbox
    c = 0.5 * (lo + hi)
    radius = 0.5 * mesh.scale * margin
    up = (0.0, 1.0, 0.0) if abs(d[1]) < 0.9 else (0.0, 0.0, 1.0)
    if kind == "orthographic":
        return Camera("orthographic", tuple(c - 2 * radius * d), tuple(c), up, ortho_height=2 * radius)
    fov = _camera_number(fov_deg, "camera fov")
    if not 0.0 < fov < 180.0:
        raise MeshshadeError(f"camera fov must lie in (0, 180) degrees, got {fov_deg!r}")
    dist = radius / np.sin(np.radians(fov) / 2)
    return Camera("perspective", tuple(c - dist * d), tuple(c), up, fov_deg=fov)


CAMERA_SYNTAX = "auto[:dx,dy,dz] | persp:eye:target:up:fov_deg | ortho:eye:target:up:height (vectors x,y,z)"


def parse_camera(spec: str, mesh, mm_per_unit: float = 1.0) -> Camera:
    """``auto`` | ``auto:dx,dy,dz`` | ``persp:ex,ey,ez:tx,ty,tz:ux,uy,uz:fov`` | ``ortho:eye:target:up:height``
    (positions and height in the mesh file's units, converted with ``mm_per_unit``).

    Raises MeshshadeError with one line naming the part that is wrong: the syntax, a vector that is not 3 finite
    numbers, a zero auto view direction, eye equal to target, a zero up vector or one parallel to the view
    direction, a fov outside (0, 180) degrees, an orthographic height that is not > 0."""
    scale = _camera_number(mm_per_unit, "mm_per_unit")
    if not 0.0 < scale < math.inf:
        raise MeshshadeError(f"mm_per_unit must be a positive finite number, got {mm_per_unit!r}")
    if not isinstance(spec, str):
        raise MeshshadeError(f"bad camera {spec!r}: {CAMERA_SYNTAX}")
    parts = [p.strip() for p in spec.strip().split(":")]
    kind = parts[0].lower()

    def vec(text, what):
        try:
            vals = [float(v) for v in text.split(",")]
        except ValueError:
            vals = []
        if len(vals) != 3:
            raise MeshshadeError(f"bad camera {spec!r}: {what} must be 3 comma-separated numbers x,y,z, got {text!r}")
        return _camera_vec3(vals, f"camera {what}")

    if kind == "auto" and len(parts) <= 2:
        return auto_camera(mesh, vec(parts[1], "auto view direction dx,dy,dz") if len(parts) == 2 else
                           (0.0, 0.0, -1.0))
    if kind in ("persp", "ortho") and len(parts) == 5:
        eye, tgt, up = vec(parts[1], "eye"), vec(parts[2], "target"), vec(parts[3], "up")
        last = "fov" if kind == "persp" else "height"
        try:
            x = float(parts[4])
        except ValueError:
            raise MeshshadeError(f"bad camera {spec!r}: the {last} must be a number, got {parts[4]!r}") from None
        eye, tgt = tuple(np.multiply(eye, scale)), tuple(np.multiply(tgt, scale))
        if kind == "persp":
            return Camera("perspective", eye, tgt, up, fov_deg=x)
        return Camera("orthographic", eye, tgt, up, ortho_height=x * scale)
    raise MeshshadeError(f"bad camera {spec!r}: {CAMERA_SYNTAX}")


# ------------------------------------------------------------------------------------------------ exit radiance
def exit_normalisation(eta: float, n: int = 256) -> float:
    """C(eta) = 2 int_0^1 F_t(eta, mu) mu dmu (Gauss-Legendre), so that int L cos dω = M."""
    x, w = np.polynomial.legendre.leggauss(n)
    mu = 0.5 * (x + 1)
    return float(np.sum(w * 0.5 * 2 * fresnel_transmittance_entry(mu, eta) * mu))


def exit_radiance(M, cos_o, eta):
    """L = F_t(eta, cos_o) M / (pi C(eta)) [W/(mm^2 sr)] for exitance M (..., 3) and outgoing cosine (...)."""
    ft = fresnel_transmittance_entry(np.clip(cos_o, 0.0, 1.0), eta)
    return np.asarray(M, float) * (ft / (np.pi * exit_normalisation(eta)))[..., None]


# ------------------------------------------------------------------------------------------------ per-pixel gather
class _Windowed:
    """A PairKernel times a smooth window of the chord (1 below near/2, smoothstep to 0 at near), so that the
    near field is smooth and the far field left to interpolation has no seam at the near radius."""

    def __init__(self, kernel, near_mm):
        self.kernel, self.near = kernel, near_mm
        self.channels, self.material = kernel.channels, kernel.material
        self.near_factors, self.source_scale = kernel.near_factors, kernel.source_scale
        self.source_drift = kernel.source_drift

    def evaluate(self, c, src, s, chord, phi, vtx=None):
        t = np.clip((chord - 0.5 * self.near) / (0.5 * self.near), 0.0, 1.0)
        return self.kernel.evaluate(c, src, s, chord, phi, vtx) * (1.0 - t * t * (3.0 - 2.0 * t))


class PixelGather:
    """Exitance at arbitrary surface points: the bake's far field, plus the near field gathered per point.

    ``M(p) = sum_c b_c [M_bake(v_c) - M_near(v_c)] + M_near(p)``, where ``M_near`` sums the kernel times a
    smooth window of the chord (1 up to ``near_mm``/2, smoothstep to 0 at ``near_mm``) over the entry samples
    (chord found by a k-d tree, turned into an arc with the source's normal
    curvature in that direction, ``s = 2 asin(|k_n| c / 2) / |k_n|``, exact on a sphere) and the bracket is
    interpolated with the hit's barycentrics. The sharp part of the kernel (a beam's peak, the patch of each
    vertex sample) is thus evaluated at the pixel itself, while the smooth far field keeps the bake's geodesic
    distances (no leaks through thin parts beyond ``near_mm``). At a vertex it equals the bake exactly.
    ``near_mm`` defaults to 16 mean edge lengths for up to 4096 entry samples (beams), else 8.

    With the volume model (``result.volume``) ``M_near`` is its correction (docs/physics.md eq. (103)) of the point
    entries, with the mean patch radius of its sampling surface as the receiver's, and the rest of the solution is
    interpolated P1 on the sampling surface (``result.sample_exitance``: the mesh split where it is coarser than
    the volume resolves, :class:`meshshade.volume.surface.SamplingSurface`), not on the input's triangles; the
    bake's vertices are that solution at their points, so here too a pixel at a vertex equals the bake.

    Only *point* entry samples (beams, inside triangles) are gathered per pixel: vertex samples (directional and
    point lights) stand for their vertex's patch, their exitance is smooth on the scale of an edge, and the
    transport's ring-averaged patch kernel evaluated between vertices is biased low (measured -4.7 % mean on the
    demo pebble), so for them per-pixel equals per-vertex interpolation.
    """

    def __init__(self, mesh, result, *, near_mm=None, max_pairs=3_000_000):
        self.volume = getattr(result, "volume", None)
        if self.volume is not None:   # the volume model: its solution on its sampling surface, P1 between the
            s = self.samples = result.samples            # samples, plus its correction (eq. (103)) of point entries
            self.surface = self.volume.surface
            S = self.surface.samples
            self.src_index = np.flatnonzero(s.vertex < 0)
            self._normals, self._vtree = S.vertex_normals, cKDTree(S.vertices)
            self._radius = float(np.sqrt(np.mean(S.vertex_areas) / np.pi))
            Ms = getattr(result, "sample_exitance", None)
            Ms = np.asarray(result.radiance, float) if Ms is None else np.asarray(Ms, float)
            self.far = Ms - self.near_field(S.vertices)
            self.faces = S.faces
            return
        curv = SimpleNamespace(k1=result.k1, k2=result.k2, d1=result.d1)
        self.samples = result.samples
        self.frames = source_frames(result.samples, curv, mesh.faces)
        beam = getattr(result, "stats", {}).get("near_field") == "beam"   # the bake's near field, at each pixel
        self.kernel = PairKernel(result.model, result.material, self.frames, plan=getattr(result, "plan", None),
                                 near=near_field_factors(result.material) if beam else None)
        if beam:
            self.kernel.source_scale = self.kernel.near_factors.incidence_scale(result.samples.cos_incidence)
            self.kernel.source_drift = drift_angles(
                refracted_drift(self.frames.normals, result.samples.directions, result.material.eta),
                self.frames.d1, self.frames.d2)
        if near_mm is None:  # few sources (beams): a wide near field is cheap and takes the peak's whole shoulder
            near_mm = (16.0 if len(result.samples) <= 4096 else 8.0) * mesh.mean_edge_length
        self.near_mm = float(near_mm)
        self.cut = np.minimum(np.asarray(result.cutoff_mm, float), self.near_mm)
        s = self.samples
        self.radius = source_patch_radius(s, mesh.vertex_areas)
        self.max_pairs = max_pairs
        self.faces = mesh.faces
        # only point samples (beams, inside triangles) have a peak sharper than the mesh: vertex samples stand for
        # their vertex's patch, and the ring-averaged kernel between vertices is biased low (~5 % on a pebble)
        self.src_index = np.flatnonzero(s.vertex < 0)
        self.tree = cKDTree(s.positions[self.src_index]) if self.src_index.size else None
        self.far = np.asarray(result.radiance, float) - self.near_field(mesh.vertices)

    def near_field(self, points) -> np.ndarray:
        """(k, 3) mm points -> (k, 3) W/mm^2: the kernel summed over entry samples within ``near_mm``."""
        points = np.asarray(points, float)
        if self.volume is not None:
            if self.src_index.size == 0 or len(points) == 0:
                return np.zeros((len(points), 3))
            normals = self._normals[self._vtree.query(points)[1]]
            return self.volume.point_entries_correction(self.samples, self.src_index, points, normals,
                                                        np.full(len(points), self._radius))
        if self.tree is None or len(points) == 0:
            return np.zeros((len(points), 3))
        pos = self.samples.positions[self.src_index]
        density = max(1.0, len(pos) * (self.near_mm / max(np.ptp(pos, axis=0).max(), 1e-9)) ** 2)
        chunk = int(max(256, self.max_pairs // density))
        f = self.frames

        def pairs():
            for a in range(0, len(points), chunk):
                sub = points[a:a + chunk]
                m = self.tree.sparse_distance_matrix(cKDTree(sub), self.cut.max(), output_type="ndarray")
                src, pix, chord = m["i"].astype(np.int64), m["j"].astype(np.int64), m["v"]
                v = sub[pix] - pos[src]
                src = self.src_index[src]
                phi = np.arctan2(np.einsum("ij,ij->i", v, f.d2[src]), np.einsum("ij,ij->i", v, f.d1[src]))
                kn = np.abs(f.k1[src] * np.cos(phi) ** 2 + f.k2[src] * np.sin(phi) ** 2)
                with np.errstate(divide="ignore", invalid="ignore"):
                    arc = 2.0 * np.arcsin(np.clip(kn * chord / 2, 0.0, 1.0)) / kn
                yield src, a + pix, np.where(kn * chord > 1e-8, arc, chord), chord, phi

        M, _ = gather(_Windowed(self.kernel, self.near_mm), len(points), self.samples.power, self.cut, pairs(),
                      source_radius=self.radius)
        return M

    def __call__(self, points, face, bary) -> np.ndarray:
        """Surface points (k, 3) mm on faces (k,) with barycentrics (k, 3) -> (k, 3) W/mm^2 exitance."""
        if self.volume is not None:
            face, bary = self.surface.locate(face, bary)
        far = np.einsum("ij,ijk->ik", np.asarray(bary, float), self.far[self.faces[face]])
        return far + self.near_field(points)


# ------------------------------------------------------------------------------------------------ rendering
#: pixels per band of :func:`render_radiance`: each pass over the image goes band by band, so that every ray-cast
#: and array operation takes a small fraction of a second and Ctrl-C acts between them (the result does not
#: depend on it: every pixel sample is computed on its own and added in the same order)
BAND_PIXELS = 1 << 20

def sample_offsets(spp: int, rng) -> np.ndarray:
    """(spp, 2) jittered stratified sub-pixel offsets in [0, 1)."""
    n = int(np.ceil(np.sqrt(spp)))
    g = np.stack(np.meshgrid(np.arange(n), np.arange(n), indexing="xy"), -1).reshape(-1, 2)[:spp]
    # the tiny irrational shift keeps pixel centres off mesh vertices that sit exactly on a pixel centre (Embree's
    # robust mode can let a ray aimed exactly at a vertex slip through, see raycast.first_hit)
    shift = 1e-4 * np.array([np.sqrt(2.0), np.sqrt(3.0)]) - 1e-4
    return ((g + rng.random((spp, 2))) / n if spp > 1 else np.full((1, 2), 0.5)) + shift


#: peak memory of :func:`render_radiance` per pixel (measured ~345 bytes at 256^2 and 512^2, 4 spp, with rays,
#: hits and per-sample arrays alive at once; the final EXR/PNG arrays add ~170), rounded up
RENDER_BYTES_PER_PIXEL = 512
#: most pixel samples (width x height x spp) of a render: 2^32, about half an hour at the ~2.3 M samples/s
#: measured on 2 cores (512^2 x 4 spp in 0.45 s, docs/benchmarks.md#images)
MAX_PIXEL_SAMPLES = 1 << 32


def _image_count(value, name: str) -> int:
    ok = not isinstance(value, (bool, str)) and isinstance(value, (int, float, np.integer, np.floating))
    if ok and not isinstance(value, (int, np.integer)):
        ok = math.isfinite(value) and float(value).is_integer()
    if not ok or int(value) < 1:
        raise MeshshadeError(f"{name} must be an integer >= 1, got {value!r}")
    return int(value)


def render_memory_limit() -> int:
    """Bytes a render may use: the physical memory free now (``os.sysconf``), but at least half of the machine's
    physical memory (the kernel reclaims its page cache on demand); 16 GiB where sysconf cannot tell."""
    try:
        page = os.sysconf("SC_PAGE_SIZE")
        return int(max(os.sysconf("SC_AVPHYS_PAGES"), os.sysconf("SC_PHYS_PAGES") // 2) * page)
    except (ValueError, OSError, AttributeError):
        return 16 << 30


def check_image_size(width, height, spp) -> tuple[int, int, int]:
    """Validate an image size before any work: ``width``, ``height`` and ``spp`` integers >= 1, at most
    ``MAX_PIXEL_SAMPLES`` pixel samples, and the estimated memory (``RENDER_BYTES_PER_PIXEL`` per pixel) within
    :func:`render_memory_limit`. One-line MeshshadeError with the estimate otherwise; returns the three ints."""
    width, height = _image_count(width, "image width"), _image_count(height, "image height")
    spp = _image_count(spp, "spp (samples per pixel)")
    need, limit = width * height * RENDER_BYTES_PER_PIXEL, render_memory_limit()
    if need > limit:
        raise MeshshadeError(f"a {width} x {height} image needs about {need / 2**30:.3g} GiB "
                             f"({RENDER_BYTES_PER_PIXEL} bytes per pixel), more than the {limit / 2**30:.3g} GiB "
                             "of memory available: use a smaller width and height")
    if width * height * spp > MAX_PIXEL_SAMPLES:
        raise MeshshadeError(f"{width} x {height} pixels x {spp} spp = {width * height * spp:.3g} pixel samples "
                             f"exceed the limit of 2^32 = {MAX_PIXEL_SAMPLES:.3g} (about half an hour at ~2.3 M "
                             "samples/s on 2 cores): use fewer pixels or samples per pixel")
    return width, height, spp


def render_radiance(mesh, vertex_radiance, camera: Camera, width: int = 512, height: int = 512, spp: int = 4, *,
                    eta: float = 1.3, exitance_at=None, scene=None, seed: int = 0):
    """Render radiance toward ``camera``.

    Parameters
    ----------
    mesh : Mesh (mm); vertex_radiance : (n, 3) W/mm^2 exitance M per vertex (the bake's ``radiance``)
    exitance_at : optional callable (points (k, 3), faces (k,), bary (k, 3)) -> (k, 3) exitance, e.g.
        :class:`PixelGather`: per-pixel mode
    spp : samples per pixel (jittered strata, seeded by ``seed``) for antialiasing
    width, height, spp : integers >= 1 within the memory and pixel-sample limits of :func:`check_image_size`
        (checked first, before any work: MeshshadeError with the estimate)

    Returns
    -------
    rgb : (H, W, 3) float64, radiance W/(mm^2 sr), premultiplied by coverage (background 0)
    alpha : (H, W) float64 coverage in [0, 1]; a camera that sees none of the mesh gives a warning naming the
    camera and the mesh's bounds
    """
    width, height, spp = check_image_size(width, height, spp)
    if not isinstance(camera, Camera):
        raise MeshshadeError(f"camera must be a Camera, got {type(camera).__name__}")
    scene = scene or make_scene(mesh.vertices, mesh.faces)
    rng = np.random.default_rng(seed)
    off = sample_offsets(spp, rng)
    jj, ii = np.meshgrid(np.arange(width), np.arange(height), indexing="xy")
    rgb = np.zeros((height, width, 3))
    alpha = np.zeros((height, width))
    aspect = width / height
    M_v = np.asarray(vertex_radiance, float)
    rows = max(1, BAND_PIXELS // width)  # bands of whole rows: each call short, so Ctrl-C acts between them
    for ox, oy in off:
        for r0 in range(0, height, rows):
            band = slice(r0, r0 + rows)
            x = (2 * (jj[band] + ox) / width - 1).reshape(-1)
            y = (1 - 2 * (ii[band] + oy) / height).reshape(-1)
            o, d = camera.rays(x, y, aspect)
            hits = scene.first_hit(o, d)
            h = hits.hit
            if not np.any(h):
                continue
            F = mesh.faces[hits.face[h]]
            b = hits.bary[h]
            if exitance_at is None:
                M = np.einsum("ij,ijk->ik", b, M_v[F])
            else:
                M = exitance_at(hits.points[h], hits.face[h], b)
            n = np.einsum("ij,ijk->ik", b, mesh.vertex_normals[F])
            n /= np.linalg.norm(n, axis=1, keepdims=True)
            cos_o = np.abs(np.einsum("ij,ij->i", n, d[h]))
            L = exit_radiance(M, cos_o, eta)
            flat = np.flatnonzero(h)
            rgb[band].reshape(-1, 3)[flat] += L  # rows of a C-ordered image: views, added in place
            alpha[band].reshape(-1)[flat] += 1.0
    if not np.any(alpha > 0):
        lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
        warnings.warn(f"the {camera.kind} camera at {_mm(camera.eye)} looking at {_mm(camera.target)} sees none of "
                      f"the mesh (bounds {_mm(lo)} to {_mm(hi)} mm): the image is empty (transparent)",
                      stacklevel=2)
    return rgb / spp, alpha / spp


def _mm(v):
    return "(" + ", ".join(f"{float(x):.4g}" for x in v) + ")"


def image_rgba(rgb, alpha) -> np.ndarray:
    """(H, W, 4) float32 premultiplied RGBA for the EXR."""
    return np.concatenate([rgb, alpha[..., None]], axis=-1).astype(np.float32)


def display_rgba(rgb, alpha, *, operator="drago", bias=0.85, exposure=None, background=None) -> np.ndarray:
    """(H, W, 4) uint8 PNG: straight-alpha tone-mapped colours; ``background`` (3,) display [0, 1] composites
    onto that colour (alpha 255), None keeps the background transparent."""
    cov = alpha > 0
    straight = np.where(cov[..., None], rgb / np.where(cov, alpha, 1.0)[..., None], 0.0)
    try:
        disp = tonemap_linear(straight, operator=operator, bias=bias, exposure=exposure, mask=cov)
    except ValueError as exc:
        raise MeshshadeError(str(exc)) from None
    enc = srgb_encode(disp)
    if background is None:
        out = np.concatenate([enc, alpha[..., None]], axis=-1)
    else:
        bg = np.asarray(background, float)
        out = np.concatenate([enc * alpha[..., None] + bg * (1 - alpha[..., None]),
                              np.ones(alpha.shape + (1,))], axis=-1)
    return np.round(np.clip(out, 0, 1) * 255).astype(np.uint8)
