"""The varying medium of a Monte Carlo walk: a painted material or a material of parts, read at any point inside
the mesh by compiled code (docs/physics.md §17, "The Monte Carlo in a varying medium").

A walk in a varying medium (:mod:`meshshade.montecarlo.varying_walk`) asks, at each tentative collision, for the
medium at that point: its extinction sigma_t (1/mm), single-scattering albedo sigma_s / sigma_t and anisotropy g,
for one channel group. :class:`MediumField` holds what that needs, and :func:`medium_at` answers inside compiled code.

*Painted* (:class:`~meshshade.painted.PaintedMaterial`): the medium of the nearest point of the input mesh's surface
(§17: "each point of the volume taking the medium of the nearest surface point"), found exactly by the triangle
hierarchy's closest-point search (:func:`meshshade.volume.triangle_tree.closest_on`); the colour there as
:meth:`PaintedMaterial.colour_at <meshshade.painted.PaintedMaterial.colour_at>` reads it (vertex colours
interpolated by the barycentrics, or the image bilinear at the interpolated UV, wrapped, v up); the reduced albedo
alpha' of that colour by eq. (106) (:func:`meshshade.kernels.painted_reflectance.albedo_for_reflectance`) through a
table (:func:`albedo_table`: linear between nodes uniform in the colour plus the colours where eq. (105)'s fitted
strengths have their kinks, refined until its error, measured against eq. (106) at every interval's midpoint, is at
most ``TABLE_TOLERANCE`` relative); then, with the base's sigma_t', eta and g, sigma_s = alpha' sigma_t' / (1 - g),
sigma_a = (1 - alpha') sigma_t'. With g = 0, sigma_t = sigma_t' everywhere: only the albedo varies.

*Parts* (:class:`~meshshade.parts.PartedMaterial`): the medium of the part owning the point, the innermost part whose
own winding number there is above 1/2 in magnitude
(:meth:`PartedMaterial.part_at <meshshade.parts.PartedMaterial.part_at>`: the same trees, the same expansion,
``WINDING_BETA``; a point that numerically lies in no part, next to the boundary,
takes the part of the largest winding number in magnitude). The acceleration is exact: a voxel grid of labels
(:func:`part_label_grid`) whose voxel holds the owner of its centre only where that owner is provably the owner of
every point of the medium in the voxel, and -1 (the winding numbers are evaluated) elsewhere. The proof: every part
must be closed (each edge of its faces used by two of them; otherwise the grid is left empty, since an open part's
winding number varies away from its faces), and the ball about the voxel's centre through its corners must meet no
face of any other part and no face of the owner that has the medium on both sides (a face the walk leaves out):
then every other part's winding number is constant in the ball, the owner's changes only across faces that bound
the medium, and a point of the medium in the ball that the owner's winding number left would lie in another part
containing the whole ball, which would make that face one with the medium on both sides.

The majorant of a channel group is the largest sigma_t of its medium (times ``MAJORANT_FACTOR``, 1 except in tests
that exercise null collisions); ``constant`` marks a group whose sigma_t is the majorant everywhere, so that no
tentative collision is null and no random number is drawn to decide it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np

from meshshade.errors import MaterialError
from meshshade.geometry.mesh import Mesh
from meshshade.kernels import near_field_table
from meshshade.kernels.painted_reflectance import albedo_for_reflectance, model_total_reflectance
from meshshade.materials import Material
from meshshade.montecarlo.boundary import welded_ids
from meshshade.painted import PaintedMaterial
from meshshade.parts import PartedMaterial
from meshshade.volume.triangle_tree import TriangleTree, closest_on, winding_at

__all__ = ["MediumField", "albedo_table", "medium_fields", "medium_at", "medium_at_points", "part_label_grid",
           "TABLE_TOLERANCE", "MAJORANT_FACTOR", "PART_GRID_VOXELS", "WINDING_BETA", "PAINTED", "PARTS",
           "is_varying", "walk_mesh"]

PAINTED, PARTS = 1, 2
#: the albedo table's largest relative error in alpha' (and in 1 - alpha'), measured at the intervals' midpoints
TABLE_TOLERANCE = 1e-6
#: the table's first node count (uniform in the colour), doubled until TABLE_TOLERANCE holds, at most _TABLE_MAX
_TABLE_NODES, _TABLE_MAX = 4097, 1 << 21
#: the majorant is this times the largest sigma_t of the medium (a test raises it to exercise null collisions)
MAJORANT_FACTOR = 1.0
#: voxels of the part-label grid (about; cubic voxels over the mesh's box)
PART_GRID_VOXELS = 1 << 18
#: PartedMaterial.part_at's winding-number accuracy (TriangleTree.winding's default beta)
WINDING_BETA = 2.0
_OPTS = dict(cache=True, error_model="numpy")


def is_varying(material) -> bool:
    """Whether ``material`` is a varying medium the Monte Carlo walks with :mod:`meshshade.montecarlo.varying_walk`."""
    return isinstance(material, (PaintedMaterial, PartedMaterial))


# ------------------------------------------------------------------------------------------------ the albedo table
def albedo_table(lo: float, hi: float, eta: float, g: float, tol: float = TABLE_TOLERANCE):
    """The reduced albedo of eq. (106) as a table over the colours [lo, hi] (one channel's paint).

    Nodes: ``n`` uniform in the colour, plus the colours where eq. (105)'s fitted strengths, linear in
    x = log10(1 - alpha') between the near-field table's nodes, have kinks (there the inverse is not smooth);
    alpha' solved at each (:func:`albedo_for_reflectance`). Linear interpolation's error is measured at every
    interval's midpoint against eq. (106) solved there, relative in alpha' and in 1 - alpha'; ``n`` doubles until
    it is at most ``tol``.

    Returns (nodes (k,), alpha' (k,), bucket start (nb + 1,) int64, (lo, 1/bucket width), measured error): the
    nodes sorted; bucket j of the uniform buckets over [lo, hi] starts its search at node ``start[j]``.
    """
    lo, hi = float(lo), float(hi)
    if not hi > lo:
        a = float(albedo_for_reflectance(np.array([lo]), eta, g)[0])
        return np.array([lo, lo]), np.array([a, a]), np.zeros(2, dtype=np.int64), (lo, 0.0), 0.0
    kinks = model_total_reflectance(1.0 - 10.0 ** near_field_table.X_NODES, eta, g)
    kinks = kinks[(kinks > lo) & (kinks < hi)]
    n = _TABLE_NODES
    while True:
        c = np.unique(np.concatenate([np.linspace(lo, hi, n), kinks]))
        a = albedo_for_reflectance(c, eta, g)
        mid = 0.5 * (c[1:] + c[:-1])
        exact = albedo_for_reflectance(mid, eta, g)
        lin = 0.5 * (a[1:] + a[:-1])
        err = float(max(np.max(np.abs(lin / exact - 1.0)), np.max(np.abs((1.0 - lin) / (1.0 - exact) - 1.0))))
        if err <= tol or n >= _TABLE_MAX:
            break
        n = 2 * (n - 1) + 1
    if err > tol:
        raise MaterialError(f"the painted albedo table reaches {err:.2g} relative error over [{lo:.4g}, {hi:.4g}] "
                            f"(wanted {tol:g})")
    nb = n - 1
    inv = nb / (hi - lo)
    edges = lo + np.arange(nb + 1) / inv
    start = np.clip(np.searchsorted(c, edges, side="right") - 1, 0, c.size - 2).astype(np.int64)
    return c, a, start, (lo, inv), err


@numba.njit(inline="always", **_OPTS)
def _table_albedo(C, nodes, alb, start, c0, inv):
    """Linear interpolation of the albedo table at colour C (clamped to its ends)."""
    k = nodes.size
    if C <= nodes[0]:
        return alb[0]
    if C >= nodes[k - 1]:
        return alb[k - 1]
    j = int((C - c0) * inv)
    j = min(max(j, 0), start.size - 1)
    i = start[j]
    while i < k - 2 and nodes[i + 1] <= C:
        i += 1
    t = (C - nodes[i]) / (nodes[i + 1] - nodes[i])
    return alb[i] + t * (alb[i + 1] - alb[i])


# ------------------------------------------------------------------------------------------------ the field
@dataclass
class MediumField:
    """One channel group's varying medium (module docstring), as the compiled walk reads it.

    kind : PAINTED or PARTS; majorant : 1/mm; constant : sigma_t equals the majorant everywhere; fp : float64
    parameters (see :func:`medium_at`); paint, parts : tuples of arrays (the other kind's are empty stand-ins);
    table_error : the albedo table's measured relative error (painted); grid_fraction : fraction of the part grid's
    voxels with a label (parts); notes : what was built, for a summary.
    """

    kind: int
    majorant: float
    constant: bool
    fp: np.ndarray
    paint: tuple
    parts: tuple
    table_error: float = 0.0
    grid_fraction: float = 0.0
    notes: dict = field(default_factory=dict)


def _empty_paint():
    z3 = np.zeros((0, 3))
    zi = np.zeros(1, dtype=np.int64)
    return (z3, z3, z3, zi, zi, np.full(1, -1, dtype=np.int64), np.zeros((1, 6)), zi, np.zeros((0, 3), np.int64),
            np.zeros(0), np.zeros((0, 3, 2)), np.zeros((0, 0)), np.zeros(2), np.zeros(2), np.zeros(2, np.int64),
            np.zeros(0), np.zeros((0, 0)))


def _empty_parts():
    z3 = np.zeros((0, 3))
    zi = np.zeros(1, dtype=np.int64)
    return (z3, z3, z3, zi, zi, np.full(1, -1, dtype=np.int64), np.zeros((1, 3)), np.zeros((1, 9)),
            np.zeros((1, 18)), np.zeros((1, 3)), np.zeros(1), zi, zi, np.full((1, 1, 1), -1, dtype=np.int8),
            np.zeros((1, 3)))


@numba.njit(inline="always", **_OPTS)
def medium_at(x, y, z, kind, fp, paint, parts, stack):
    """(sigma_t 1/mm, single-scattering albedo, g) of one channel group's medium at (x, y, z) (module docstring).

    fp[0] majorant, fp[1] 1 if sigma_t is constant (then the majorant is returned as sigma_t);
    painted: fp[2] sigma_t', fp[3] g, fp[4] 1 for an image (else vertex colours), fp[5], fp[6] the table's bucket
    origin and 1/width, fp[7] the radius map (0 none, 1 per vertex, 2 an image: sigma_t' over its factor, eq.
    (132)); parts: fp[2:5] the label grid's origin, fp[5] 1/voxel, fp[6] the winding accuracy beta.
    ``stack``: an int64 work array of 256.
    """
    if kind == PAINTED:
        TA, TB, TC, Tlo, Thi, Tchild, Tbox, Torder, MF, col, uv, img, nodes, alb, start, rcol, rimg = paint
        t, v, w, _d2 = closest_on(x, y, z, TA, TB, TC, Tlo, Thi, Tchild, Tbox, stack)
        f = Torder[t]
        b0 = 1.0 - v - w
        uu = vv = 0.0
        if fp[4] > 0.0 or fp[7] == 2.0:
            uu = b0 * uv[f, 0, 0] + v * uv[f, 1, 0] + w * uv[f, 2, 0]
            vv = b0 * uv[f, 0, 1] + v * uv[f, 1, 1] + w * uv[f, 2, 1]
        if fp[4] > 0.0:
            C = _bilinear(img, uu, vv)
        else:
            C = b0 * col[MF[f, 0]] + v * col[MF[f, 1]] + w * col[MF[f, 2]]
        a = min(1.0, max(0.0, _table_albedo(C, nodes, alb, start, fp[5], fp[6])))
        g = fp[3]
        if fp[1] > 0.0:        # g = 0 and no radius map: sigma_t = sigma_t', the albedo is alpha'
            return fp[0], a, g
        st_p = fp[2]
        if fp[7] == 1.0:
            st_p /= b0 * rcol[MF[f, 0]] + v * rcol[MF[f, 1]] + w * rcol[MF[f, 2]]
        elif fp[7] == 2.0:
            st_p /= _bilinear(rimg, uu, vv)
        ss = a * st_p / (1.0 - g)
        st = ss + (1.0 - a) * st_p
        return st, ss / st, g
    PA, PB, PC, Plo, Phi, Pchild, PN, PM, PS, Pp, Prad, roots, asc, labels, coef = parts
    k = -1
    fa = math.floor((x - fp[2]) * fp[5])
    fb = math.floor((y - fp[3]) * fp[5])
    fc = math.floor((z - fp[4]) * fp[5])
    if 0 <= fa < labels.shape[0] and 0 <= fb < labels.shape[1] and 0 <= fc < labels.shape[2]:
        k = labels[int(fa), int(fb), int(fc)]
    if k < 0:
        best = -math.inf
        kb = asc[0]
        for j in range(asc.size):
            p = asc[j]
            wn = winding_at(x, y, z, roots[p], PA, PB, PC, Plo, Phi, Pchild, PN, PM, PS, Pp, Prad, fp[6], stack)
            wn = abs(wn)
            if wn > 0.5:
                k = p
                break
            if wn > best:
                best, kb = wn, p
        if k < 0:
            k = kb
    st = coef[k, 0]
    if fp[1] > 0.0:
        st = fp[0]
    return st, coef[k, 1], coef[k, 2]


@numba.njit(inline="always", **_OPTS)
def _bilinear(img, uu, vv):
    """One channel's image ``img`` (H, W) read bilinearly at texture coordinates (uu, vv) (wrapped in u, clamped
    in v, v up), as :meth:`PaintedMaterial.colour_at <meshshade.painted.PaintedMaterial.colour_at>` reads it."""
    H, W = img.shape[0], img.shape[1]
    px = (uu - math.floor(uu)) * W - 0.5
    py = (1.0 - (vv - math.floor(vv))) * H - 0.5
    x0, y0 = math.floor(px), math.floor(py)
    fx, fy = px - x0, py - y0
    xa, xb = int(x0) % W, int(x0 + 1) % W
    ya, yb = min(max(int(y0), 0), H - 1), min(max(int(y0) + 1, 0), H - 1)
    return (1 - fy) * ((1 - fx) * img[ya, xa] + fx * img[ya, xb]) + fy * ((1 - fx) * img[yb, xa] + fx * img[yb, xb])


@numba.njit(**_OPTS)
def _at_points(P, kind, fp, paint, parts, out):
    stack = np.empty(256, np.int64)
    for q in range(P.shape[0]):
        out[q, 0], out[q, 1], out[q, 2] = medium_at(P[q, 0], P[q, 1], P[q, 2], kind, fp, paint, parts, stack)


def medium_at_points(fld: MediumField, points) -> np.ndarray:
    """(p, 3): (sigma_t, albedo, g) of ``fld`` at ``points`` (p, 3) mm, as the walk reads them (for tests and
    measurements)."""
    P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.zeros((P.shape[0], 3))
    _at_points(P, fld.kind, fld.fp, fld.paint, fld.parts, out)
    return out


# ------------------------------------------------------------------------------------------------ painted
def _paint_channel_data(material: PaintedMaterial, c: int) -> np.ndarray:
    return material.colour[:, c] if material.colour is not None else material.image[:, :, c]


def _radius_channel_data(material: PaintedMaterial, c: int):
    if material.radius is not None:
        return material.radius[:, c]
    return None if material.radius_image is None else material.radius_image[:, :, c]


def painted_groups(material: PaintedMaterial) -> list:
    """``[(key, [channels]), ...]``: channels share a walk when the base's sigma_t', the paint's channel and the
    radius map's channel are equal."""
    groups: dict = {}
    for c in range(3):
        data = np.ascontiguousarray(_paint_channel_data(material, c))
        rad = _radius_channel_data(material, c)
        rad = b"" if rad is None else np.ascontiguousarray(rad).tobytes()
        groups.setdefault((float(material.base.sigma_t_prime[c]), data.tobytes(), rad), []).append(c)
    return list(groups.items())


def painted_field(material: PaintedMaterial, mesh, c: int, tree: TriangleTree | None = None) -> MediumField:
    """The :class:`MediumField` of channel ``c`` of ``material`` on ``mesh`` (its input faces)."""
    base = material.base
    g, eta = float(base.g), float(base.eta)
    st_p = float(base.sigma_t_prime[c])
    data = _paint_channel_data(material, c)
    lo, hi = float(np.min(data)), float(np.max(data))
    nodes, alb, start, (c0, inv), err = albedo_table(lo, hi, eta, g)
    tree = TriangleTree(mesh.vertices, mesh.faces) if tree is None else tree
    image = material.image is not None
    rad = _radius_channel_data(material, c)
    radius_kind = 0.0 if rad is None else (1.0 if material.radius is not None else 2.0)
    # writable copies: a read-only array is another type to numba, which would compile the walk once more
    col = np.zeros(0) if image else np.array(data, dtype=np.float64)
    img = np.array(data, dtype=np.float64) if image else np.zeros((0, 0))
    uv = np.array(material.uv, dtype=np.float64) if material.uv is not None else np.zeros((0, 3, 2))
    rcol = np.array(rad, dtype=np.float64) if radius_kind == 1.0 else np.zeros(0)
    rimg = np.array(rad, dtype=np.float64) if radius_kind == 2.0 else np.zeros((0, 0))
    paint = (tree.A, tree.B, tree.C, tree.lo, tree.hi, tree.child, tree.box, tree.order,
             np.array(mesh.faces, dtype=np.int64), col, uv, img, nodes, alb, start, rcol, rimg)
    # the largest sigma_t' over the paint: the base's over the radius map's least factor (interpolation stays
    # within the values, eq. (132))
    st_max = st_p / (1.0 if rad is None else float(np.min(rad)))
    if g == 0.0:
        majorant, constant = st_max, rad is None
    else:      # sigma_t = sigma_t' (1 + alpha' g / (1 - g)): largest at the largest alpha' for g > 0
        a = np.clip(alb, 0.0, 1.0)
        majorant, constant = float(np.max(a * st_max / (1.0 - g) + (1.0 - a) * st_max)), False
    majorant *= MAJORANT_FACTOR
    constant = constant and MAJORANT_FACTOR == 1.0
    fp = np.array([majorant, 1.0 if constant else 0.0, st_p, g, 1.0 if image else 0.0, c0, inv, radius_kind])
    return MediumField(PAINTED, majorant, constant, fp, paint, _empty_parts(), table_error=err,
                       notes={"table_nodes": int(nodes.size), "colour_range": (lo, hi)})


# ------------------------------------------------------------------------------------------------ parts
def part_groups(material: PartedMaterial) -> list:
    """``[(key, [channels]), ...]``: channels share a walk when every part has the same (sigma_s, sigma_a) in
    them."""
    groups: dict = {}
    for c in range(3):
        key = tuple((float(m.medium.sigma_s[c]), float(m.medium.sigma_a[c])) for m in material.materials)
        groups.setdefault(key, []).append(c)
    return list(groups.items())


def _closed(faces) -> bool:
    """Whether every edge of ``faces`` (welded ids) is used by exactly two of them."""
    if faces.shape[0] == 0:
        return True
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    return bool(np.all(counts == 2))


@dataclass
class PackedParts:
    """The parts' triangle trees packed one after another (each keeps its own root), their volumes and order."""

    arrays: tuple            # A, B, C, lo, hi, child, N, M, S, p, rad
    roots: np.ndarray
    ascending: np.ndarray    # parts by enclosed volume, least first (the innermost is met first)
    trees: list
    closed: bool


def pack_parts(material: PartedMaterial, mesh) -> PackedParts:
    V, F = mesh.vertices, mesh.faces
    trees = [TriangleTree(V, material.faces_of(k, F)) for k in range(material.n_parts)]
    tri_off = np.cumsum([0] + [t.n_tri for t in trees])
    node_off = np.cumsum([0] + [t.lo.size for t in trees])
    cat = lambda key: np.ascontiguousarray(np.concatenate([getattr(t, key) for t in trees]))  # noqa: E731
    A, B, C = cat("A"), cat("B"), cat("C")
    lo = np.concatenate([t.lo + o for t, o in zip(trees, tri_off)])
    hi = np.concatenate([t.hi + o for t, o in zip(trees, tri_off)])
    child = np.concatenate([np.where(t.child >= 0, t.child + o, -1) for t, o in zip(trees, node_off)])
    arrays = (A.reshape(-1, 3), B.reshape(-1, 3), C.reshape(-1, 3), lo, hi, child, cat("N"), cat("M"), cat("S"),
              cat("p"), cat("rad"))
    vol = material.enclosed_volumes(V, F)
    # part_at's order reversed: largest first there with the later one winning ties, least first here with the
    # first one winning (the same owner)
    ascending = np.argsort(vol, kind="stable").astype(np.int64)
    ids = welded_ids(V)
    closed = all(_closed(ids[material.faces_of(k, F)]) for k in range(material.n_parts))
    return PackedParts(arrays, node_off[:-1].astype(np.int64), ascending, trees, closed)


def part_label_grid(material: PartedMaterial, mesh, packed: PackedParts, medium_faces, voxels=None):
    """(labels (nx, ny, nz) int8, origin (3,), 1/h, fraction labelled): the part owning every point of the medium
    in each voxel, or -1 where that is not proven (module docstring). ``medium_faces`` (m,) bool: the mesh faces
    that bound the medium (the walk's faces); the others have the medium on both sides (or neither)."""
    voxels = PART_GRID_VOXELS if voxels is None else voxels
    V = np.asarray(mesh.vertices, dtype=np.float64)
    lo, hi = V.min(axis=0), V.max(axis=0)
    ext = np.maximum(hi - lo, 1e-9)
    h = float((np.prod(ext) / voxels) ** (1.0 / 3.0))
    n = np.maximum(1, np.ceil(ext / h).astype(np.int64))
    if not packed.closed or material.n_parts > 127:
        return np.full((1, 1, 1), -1, dtype=np.int8), lo, 1.0 / h, 0.0
    ax = [lo[d] + (np.arange(n[d]) + 0.5) * h for d in range(3)]
    P = np.stack(np.meshgrid(*ax, indexing="ij"), axis=-1).reshape(-1, 3)
    owner = material.part_at(V, mesh.faces, P)
    half = 0.5 * math.sqrt(3.0) * h
    F = np.asarray(mesh.faces)
    fp = material.face_part
    ok = owner >= 0
    for k in range(material.n_parts):
        near_any = TriangleTree(V, F[fp == k]).distance(P, bound=2.0 * half) <= half
        near_inner = TriangleTree(V, F[(fp == k) & ~medium_faces]).distance(P, bound=2.0 * half) <= half
        ok &= ~np.where(owner == k, near_inner, near_any)
    labels = np.where(ok, owner, -1).astype(np.int8).reshape(tuple(n))
    return labels, lo, 1.0 / h, float(np.mean(ok))


def parts_field(material: PartedMaterial, mesh, c: int, packed: PackedParts, grid) -> MediumField:
    """The :class:`MediumField` of channel ``c`` of ``material`` (``grid``: :func:`part_label_grid`'s result)."""
    coef = np.zeros((material.n_parts, 3))
    for k, m in enumerate(material.materials):
        ss, sa = float(m.medium.sigma_s[c]), float(m.medium.sigma_a[c])
        st = ss + sa
        coef[k] = st, (ss / st if st > 0 else 0.0), float(m.g)
    top = float(coef[:, 0].max())
    majorant = top * MAJORANT_FACTOR
    constant = bool(np.all(coef[:, 0] == top)) and MAJORANT_FACTOR == 1.0
    labels, origin, inv_h, frac = grid
    fp = np.array([majorant, 1.0 if constant else 0.0, origin[0], origin[1], origin[2], inv_h, WINDING_BETA])
    parts = (*packed.arrays, packed.roots, packed.ascending, labels, coef)
    return MediumField(PARTS, majorant, constant, fp, _empty_paint(), parts, grid_fraction=frac,
                       notes={"grid": labels.shape, "grid_fraction": frac, "closed": packed.closed})


# ------------------------------------------------------------------------------------------------ entry
def common_eta(material) -> float:
    """The index of refraction at the object's boundary: the base's (painted), or the parts' common one (a
    MaterialError for parts of different indices: the walk's entry and exit take one index)."""
    if isinstance(material, PaintedMaterial):
        return float(material.base.eta)
    etas = {float(m.eta) for m in material.materials}
    if len(etas) > 1:
        raise MaterialError("the Monte Carlo walks parts of one index of refraction (their boundary's Fresnel "
                            f"takes one); these have {', '.join(f'{e:g}' for e in sorted(etas))}")
    return etas.pop()


def walk_mesh(material, mesh):
    """The mesh whose inside the walk takes as the medium: ``mesh`` itself, or for parts ``mesh`` with each part
    wound outward (:meth:`PartedMaterial.outward_faces <meshshade.parts.PartedMaterial.outward_faces>`: a nested
    part is no cavity; the faces' indices are kept)."""
    if not isinstance(material, PartedMaterial):
        return mesh
    F, turned = material.outward_faces(mesh.vertices, mesh.faces)
    if not np.any(turned):
        return mesh
    return Mesh(mesh.vertices, F, mm_per_unit=mesh.mm_per_unit, source=mesh.source, defects=mesh.defects)


def medium_fields(material, mesh, medium_faces=None, *, grid_voxels=None) -> tuple[list, list]:
    """(channel groups ``[(key, [channels]), ...]``, one :class:`MediumField` per group) of a painted or parted
    ``material`` on ``mesh``; ``medium_faces`` (m,) bool the mesh faces the walk bounds the medium with (parts'
    label grid; default all)."""
    if isinstance(material, PaintedMaterial):
        material.check_mesh(mesh)
        groups = painted_groups(material)
        tree = TriangleTree(mesh.vertices, mesh.faces)
        return groups, [painted_field(material, mesh, chans[0], tree) for _key, chans in groups]
    if isinstance(material, PartedMaterial):
        material.check_mesh(mesh)
        groups = part_groups(material)
        packed = pack_parts(material, mesh)
        mf = np.ones(mesh.n_faces, dtype=bool) if medium_faces is None else np.asarray(medium_faces, dtype=bool)
        grid = part_label_grid(material, mesh, packed, mf, grid_voxels)
        return groups, [parts_field(material, mesh, chans[0], packed, grid) for _key, chans in groups]
    if isinstance(material, Material):
        raise MaterialError("a homogeneous Material has no varying medium")
    raise MaterialError(f"Monte Carlo needs a Material, PaintedMaterial or PartedMaterial, got "
                        f"{type(material).__name__}")
