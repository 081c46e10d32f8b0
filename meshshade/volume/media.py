"""A medium that varies over the object, as the volume transport reads it (docs/physics.md §17): one interface,
two kinds.

The volume transport (:mod:`meshshade.volume.transport`) of one homogeneous :class:`~meshshade.materials.Material`
keeps its own path (constants in the operator's coefficients, one table of the near field). A varying medium is
read through a :class:`VaryingMedium`, which answers the questions the transport asks:

* :meth:`~VaryingMedium.resolution_material`: what the lattice must resolve (its fastest and slowest decays);
* :meth:`~VaryingMedium.attach`: the medium at the sampling surface's vertices (the receivers) and the near
  field's tables;
* :meth:`~VaryingMedium.cube_media`: D and sigma_a per cube of the lattice (eq. (107));
* :meth:`~VaryingMedium.entry_loads`: the lattice's line sources of each entry, in the medium where it enters;
* :meth:`~VaryingMedium.near_field` / :meth:`~VaryingMedium.point_near_field`: eq. (103) with the receiver's
  medium;
* :meth:`~VaryingMedium.extinction` / :meth:`~VaryingMedium.extinction_at` / :meth:`~VaryingMedium.least_extinction`:
  what the light crossing unscattered sees (eq. (130)).

Two kinds: :class:`PaintedMedium` (a :class:`~meshshade.painted.PaintedMaterial`: the albedo, and with a radius
map the mean free path, painted on the surface, each point of the volume the medium of the nearest sampled surface
point, the near field tabulated at a few albedos and mean free paths and interpolated, eqs. (108), (133)) and
:class:`PartsMedium` (a :class:`~meshshade.parts.PartedMaterial`: each point the medium of the part owning it,
the near field tabulated per distinct medium, §17 "Parts").

Pure array work; no I/O.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
from scipy.spatial import cKDTree

from meshshade.kernels.painted_reflectance import albedo_for_reflectance
from meshshade.painted import PaintedMaterial
from meshshade.pacing import default_threads
from meshshade.volume.long_range import ewald_weight, lattice_loads, line_rule
from meshshade.volume.remainder import RemainderTables, remainder_exitance
from meshshade.volume.resolution import REFINE_EFOLDS

__all__ = ["VaryingMedium", "PaintedMedium", "PartsMedium", "varying_medium", "NEAR_FIELD_NODES"]

#: a painted medium's near field is tabulated at this many reduced albedos per channel (spread evenly in
#: log10(1 - alpha') over the paint's range) and interpolated at each receiver (docs/physics.md eq. (108))
NEAR_FIELD_NODES = 3
#: with a radius map, the near field's nodes in ln sigma_t' are at most this far apart (and at least
#: NEAR_FIELD_NODES, at most MFP_NODES_MAX): a 15 mm ball of skin1 whose mean free path runs 0.6-1.5x its own across
#: it (a ratio of 2.5) bakes 0.46 / 0.11 % off (90th percentile over the lit vertices) with 3 / 5 nodes against 9,
#: eq. (133)'s error falling as the square of the spacing (2 nodes: 2.1 %)
MFP_NODE_STEP = math.log(1.25)
MFP_NODES_MAX = 9
#: a pair of a painted medium weighs the entry's power by f in the entry's medium (eq. (134)); False: the
#: receiver's for the whole pair (eq. (108) alone)
ENTRY_MEDIUM = True


def varying_medium(material):
    """The :class:`VaryingMedium` of ``material``, or None for a homogeneous Material (the transport's own path)."""
    if isinstance(material, PaintedMaterial):
        return PaintedMedium(material)
    if hasattr(material, "face_part") and hasattr(material, "part_at"):
        # a meshshade.parts.PartedMaterial (recognised by its record, not imported: parts reads the volume's
        # winding numbers, so the volume importing parts would be a cycle between the stages)
        return PartsMedium(material)
    return None


class VaryingMedium:
    """The interface (module docstring). ``boundary`` is the Material whose A (eq. (74)) sets the object's
    boundary term 1/(2A) everywhere (A depends on the index only; every kind here has one index)."""

    boundary = None
    #: per-cube media for a medium that is in fact one (tests: the same bake through the per-cube matrices)
    force_cubes = False

    def resolution_material(self):
        raise NotImplementedError

    def note_resolution(self, res, own) -> None:
        """The lattice's resolution ``res`` is chosen; ``own(material)`` is the one a material alone would have."""

    def edge_reach(self, points):
        """(p,) mm: how far around each edge of light at ``points`` the lattice is refined, or None: the
        resolution's one ``refine_radius`` (:mod:`meshshade.volume.resolution`)."""
        return None

    def attach(self, mesh, surface, spread: float):
        """Read the medium at the sampling ``surface`` of ``mesh`` and tabulate the near field at the lattice's ``spread``;
        returns the first table (the stats' radius)."""
        raise NotImplementedError

    def cube_media(self, centres):
        """(D (C, 3) mm, sigma_a (C, 3) 1/mm) at the cubes' ``centres``, or None where the medium is one."""
        raise NotImplementedError

    def entry_loads(self, lattice, samples, w, spread):
        """(loads (N, 3), dropped (3,)): the line sources (eqs. (97)-(100)) of ``samples`` entering along the
        refracted directions ``w``, each in the medium where it enters."""
        raise NotImplementedError

    def near_field(self, src, rec, spacing_mm):
        """(M_f (n_s, 3), pairs): eq. (103) at the sampling surface's vertices (``rec``) for the entries ``src``."""
        raise NotImplementedError

    def point_near_field(self, src, rec, points):
        """(p, 3): eq. (103) of the point entries ``src`` at ``points`` (receivers ``rec``), no coarse far part."""
        raise NotImplementedError

    def extinction(self):
        """(3,) 1/mm: the reduced extinction sigma_t' where it is the same everywhere, else None (then
        :meth:`extinction_at`): what the unscattered light crossing the object sees (eq. (130))."""
        raise NotImplementedError

    def extinction_at(self, points):
        """(p, 3) 1/mm: the reduced extinction sigma_t' at ``points`` (p, 3) of the volume."""
        raise NotImplementedError

    def least_extinction(self):
        """(3,) 1/mm: the least reduced extinction sigma_t' anywhere in the medium, per channel."""
        raise NotImplementedError


# ------------------------------------------------------------------------------------------------ painted
class PaintedMedium(VaryingMedium):
    """A painted material's medium (docs/physics.md §17): the reduced albedo at each sampling vertex (eq. (106)
    of the colour there) and its reduced extinction (the base's over the radius map's factor there, eq. (132)),
    each cube and entry the medium of the nearest sampling vertex, the near field at NEAR_FIELD_NODES albedos per
    channel (and as many mean free paths, with a radius map) interpolated at the receiver's (eqs. (108), (133))."""

    def __init__(self, material: PaintedMaterial):
        self.material = material
        self.boundary = material.base

    def resolution_material(self):
        # the lattice resolves the paint's fastest-decaying medium: its least albedo at its shortest mean free path
        # per channel (the two taken together wherever they lie: the decay grows with both)
        name = "the paint's darkest colour" + (" at its shortest mean free path" if self.material.has_radius else "")
        return self.material.material_of(self.material.albedo_range()[0], name,
                                         sigma_t_prime=self.material.sigma_t_prime_range()[1])

    def attach(self, mesh, surface, spread):
        p, surf = self.material, surface
        F = surf.samples.faces
        colour = np.zeros((surf.samples.n_vertices, 3))
        radius = np.ones((surf.samples.n_vertices, 3))
        for k in range(3):                                   # each corner's point on its input face
            colour[F[:, k]] = p.colour_at(surf._origin, mesh.faces, surf._bary[:, k, :])
            if p.has_radius:
                radius[F[:, k]] = p.radius_at(surf._origin, mesh.faces, surf._bary[:, k, :])
        self.sample_albedo = albedo_for_reflectance(np.clip(colour, 0.0, None), p.eta, p.g)
        self.sample_st = np.asarray(p.sigma_t_prime, dtype=np.float64) / radius
        self._tree = cKDTree(surf.samples.vertices)
        # the tables' nodes: evenly in log10(1 - alpha') and in ln sigma_t' over the sampled paint, per channel
        self._node_x = _nodes(np.log10(1.0 - self.sample_albedo))                   # (ka, 3)
        self._node_y = _nodes(np.log(self.sample_st), MFP_NODE_STEP, MFP_NODES_MAX)  # (ks, 3)
        self.tables_at = [RemainderTables(p.material_of(1.0 - 10.0 ** xn, f"painted node {i},{j}",
                                                        sigma_t_prime=np.exp(yn)), spread)
                          for i, xn in enumerate(self._node_x) for j, yn in enumerate(self._node_y)]
        return self.tables_at[0]

    def medium_at(self, points):
        """(alpha' (p, 3), D (p, 3) mm, sigma_a (p, 3) 1/mm, sigma_t' (p, 3) 1/mm) at ``points``: that of the
        nearest sampling vertex (d'Eon's D = (2 - alpha') / (3 sigma_t'))."""
        _, i = self._tree.query(points, workers=default_threads())
        a = self.sample_albedo[i]
        st = self.sample_st[i]
        return a, (2.0 - a) / (3.0 * st), (1.0 - a) * st, st

    def cube_media(self, centres):
        _, D, sig_a, _ = self.medium_at(centres)
        return D, sig_a

    def entry_loads(self, lattice, samples, w, spread):
        a, D, sig_a, st = self.medium_at(samples.positions)
        base = np.asarray(self.material.sigma_t_prime, dtype=np.float64)
        x, q = line_rule(1.0)
        power = samples.power[:, None] * a * ewald_weight(np.sqrt(sig_a / D), spread)     # (p, 3): per channel
        scale = base / st if self.material.has_radius else None                             # eq. (132)
        return lattice_loads(lattice, samples.positions, w, samples.normals, power, x[None, :] / base[:, None],
                             np.broadcast_to(q, (3, q.size)), spread, depth_scale=scale)

    def near_field(self, src, rec, spacing_mm):
        return remainder_exitance(self.tables_at, src, rec, spacing_mm=spacing_mm,
                                  blend=self._blend(self.sample_albedo, self.sample_st), src_blend=self._src_blend(src))

    def point_near_field(self, src, rec, points):
        a, _, _, st = self.medium_at(points)
        return remainder_exitance(self.tables_at, src, rec, blend=self._blend(a, st),
                                  src_blend=self._src_blend(src))[0]

    def _src_blend(self, src):
        """The entries' tables and weights (their media, the nearest sampling vertex's: eq. (134)), or None."""
        if not ENTRY_MEDIUM or src["pos"].shape[0] == 0:
            return None
        a, _, _, st = self.medium_at(src["pos"])
        return self._blend(a, st)

    def extinction(self):
        # the paint keeps the base's mean free path (eq. (106)) unless a radius map scales it (eq. (132))
        if self.material.has_radius:
            return None
        return np.asarray(self.material.sigma_t_prime, dtype=np.float64)

    def extinction_at(self, points):
        if self.material.has_radius:
            return self.medium_at(points)[3]
        return np.broadcast_to(self.extinction(), (len(points), 3))

    def least_extinction(self):
        return self.material.sigma_t_prime_range()[0]

    def _blend(self, albedo, sigma_t_prime):
        """(tables (p, 3, Q), weights (p, 3, Q)): each receiver's tables and weights per channel, linear in
        log10(1 - alpha') between the albedo nodes (eq. (108)) and in ln sigma_t' between the mean free paths'
        (eq. (133)), Q = 2 or 4 corners; the near field is summed with them in one pass
        (:func:`meshshade.volume.remainder.remainder_exitance`). None for a uniform paint (one table: the
        homogeneous sum)."""
        ka, ks = len(self._node_x), len(self._node_y)
        if ka * ks == 1:
            return None
        axes = []
        for nodes, v in ((self._node_x, np.log10(1.0 - albedo)), (self._node_y, np.log(sigma_t_prime))):
            k = len(nodes)
            if k == 1:
                axes.append([(np.zeros(v.shape, dtype=np.int64), np.ones(v.shape))])
                continue
            index = np.arange(k, dtype=np.float64)
            u = np.stack([np.interp(v[:, c], nodes[:, c], index) for c in range(3)], axis=1)
            node = np.minimum(np.floor(u).astype(np.int64), k - 2)
            axes.append([(node, 1.0 - (u - node)), (node + 1, u - node)])
        corners = [(ia * ks + js, wa * ws) for ia, wa in axes[0] for js, ws in axes[1]]
        return (np.stack([t for t, _ in corners], axis=2), np.stack([w for _, w in corners], axis=2))


def _nodes(values, step=None, most=NEAR_FIELD_NODES):
    """(k, 3): values spread evenly over each channel's range of ``values`` (p, 3): NEAR_FIELD_NODES, or with
    ``step`` as many as keep them at most ``step`` apart (at most ``most``); its one value (k = 1) where no channel
    varies."""
    lo, hi = values.min(axis=0), values.max(axis=0)
    span = float(np.max(hi - lo))
    if span < 1e-12:
        return lo[None, :]
    k = NEAR_FIELD_NODES if step is None else int(np.clip(math.ceil(span / step) + 1, NEAR_FIELD_NODES, most))
    return np.linspace(lo, hi, k)


# ------------------------------------------------------------------------------------------------ parts
def _medium_key(m):
    """What makes two parts' materials one medium: the coefficients, index and anisotropy (not the name)."""
    return (tuple(np.asarray(m.sigma_s_prime, dtype=np.float64).tolist()),
            tuple(np.asarray(m.sigma_a, dtype=np.float64).tolist()), float(m.eta), float(m.g))


class PartsMedium(VaryingMedium):
    """A material of parts (docs/physics.md §17 "Parts"): parts of equal coefficients are one medium; each cube
    takes the medium of the part owning its centre (:meth:`~meshshade.parts.PartedMaterial.part_at`, the
    innermost part whose winding number is above 1/2), each sampling vertex that of its input face's part, each
    entry that of the sampling vertex where it enters (a beam: the nearest one), and the near field at a receiver
    is tabulated in the receiver's medium, each entry's power weighed in the entry's (eq. (134)). One index for all parts (MaterialError otherwise): the internal
    interfaces are index-matched."""

    def __init__(self, material):
        self.material = material
        material.check_one_index()
        keys, self.media, index = {}, [], []
        for m in material.materials:
            k = _medium_key(m)
            if k not in keys:
                keys[k] = len(self.media)
                self.media.append(m)
            index.append(keys[k])
        self.part_medium = np.asarray(index, dtype=np.int64)          # part -> distinct medium
        self.boundary = self.media[0]

    @property
    def single(self) -> bool:
        """Whether the parts are of one medium (then the cubes' media are constants: the homogeneous matrices)."""
        return len(self.media) == 1 and not self.force_cubes

    def resolution_material(self):
        if len(self.media) == 1:
            return self.media[0]
        # every medium's decay: the fastest sets the spacing and the grading's bands, the slowest the depth
        kappa = np.concatenate([np.asarray(m.medium.kappa, dtype=np.float64) for m in self.media])
        fastest = self.media[int(np.argmax(kappa)) // 3]
        return SimpleNamespace(medium=SimpleNamespace(kappa=kappa), name=f"the part in {fastest.name}")

    def note_resolution(self, res, own) -> None:
        """Each medium's edges of light are refined as that medium alone would refine them, where the lattice's
        surface spacing does not already resolve them as finely: REFINE_EFOLDS decay lengths of its fastest
        channel, if ``res.h0`` is coarser than the spacing the medium alone has at its edges (half its own surface
        spacing ``own(medium).h0`` where it refines them, the whole where it does not:
        :data:`~meshshade.volume.resolution.EDGE_KAPPA_H`), else not at all (a marble part in a skin1 lattice:
        skin1's 0.84 mm is finer than marble's own 1 mm)."""
        def at_edges(r):
            return r.h0 * (0.5 if r.refine_radius > 0 else 1.0)

        self._reach = np.array([REFINE_EFOLDS / float(np.max(m.medium.kappa))
                                if res.h0 > at_edges(own(m)) * (1.0 + 1e-9) else 0.0 for m in self.media])

    def edge_reach(self, points):
        """(p,) mm: how far around each edge of light at ``points`` the lattice is refined (0: not at all): that of
        the medium there, its nearest sampling vertex's (:meth:`note_resolution`; the fastest medium's reach
        everywhere under-resolves a slower one's edges where they need refining: its half of a sphere of marble
        beside a more absorbing marble 3-7 % off)."""
        if len(self.media) == 1:
            return None
        _, i = self._tree.query(np.asarray(points, dtype=np.float64))
        return self._reach[self.sample_medium[i]]

    def attach(self, mesh, surface, spread):
        surf = surface
        self._mesh = mesh
        self.material.check_mesh(mesh)
        fp = self.material.face_part[surf._origin]               # each sampling face's part
        F = surf.samples.faces
        vp = np.full(surf.samples.n_vertices, -1, dtype=np.int64)
        for k in range(3):                                       # a vertex on a seam: the highest-numbered part
            np.maximum.at(vp, F[:, k], fp)
        vp[vp < 0] = 0                                           # a vertex of no face (none on a sampling surface)
        self.sample_part = vp
        self.sample_medium = self.part_medium[vp]
        self._tree = cKDTree(surf.samples.vertices)
        self.tables_at = [RemainderTables(m, spread) for m in self.media]
        return self.tables_at[0]

    def medium_at(self, points):
        """(p,) int: the medium (index into ``media``) at ``points`` (p, 3) of the volume: that of the part owning
        the point, or where none does (a point outside every part's own winding number, as a cut cube's centre
        outside the surface), of the nearest sampling vertex."""
        P = np.asarray(points, dtype=np.float64)
        part = self.material.part_at(self._mesh.vertices, self._mesh.faces, P)
        miss = np.flatnonzero(part < 0)
        if miss.size:
            _, i = self._tree.query(P[miss])
            part[miss] = self.sample_part[i]
        return self.part_medium[part]

    def cube_media(self, centres):
        if self.single:
            return None
        k = self.medium_at(centres)
        D = np.stack([np.asarray(m.medium.D, dtype=np.float64) for m in self.media])[k]
        sig_a = np.stack([np.asarray(m.sigma_a, dtype=np.float64) for m in self.media])[k]
        return D, sig_a

    def extinction(self):
        st = np.stack([np.asarray(m.sigma_t_prime, dtype=np.float64) for m in self.media])
        return st[0] if np.all(st == st[0]) else None

    def extinction_at(self, points):
        st = np.stack([np.asarray(m.sigma_t_prime, dtype=np.float64) for m in self.media])
        return st[self.medium_at(points)]

    def least_extinction(self):
        return np.min([np.asarray(m.sigma_t_prime, dtype=np.float64) for m in self.media], axis=0)

    def _src_blend(self, src):
        """The entries' media as one table each (the nearest sampling vertex's medium: eq. (134)), or None."""
        if not ENTRY_MEDIUM or src["pos"].shape[0] == 0:
            return None
        _, i = self._tree.query(np.asarray(src["pos"], dtype=np.float64))
        return _one_corner(self.sample_medium[i])

    def entry_medium(self, samples):
        """(k,) int: the medium where each entry enters (its sampling vertex's; a beam's nearest vertex's)."""
        k = np.empty(len(samples), dtype=np.int64)
        at_v = samples.vertex >= 0
        k[at_v] = self.sample_medium[samples.vertex[at_v]]
        if (~at_v).any():
            _, i = self._tree.query(samples.positions[~at_v])
            k[~at_v] = self.sample_medium[i]
        return k

    def entry_loads(self, lattice, samples, w, spread):
        where = self.entry_medium(samples)
        loads, dropped = None, np.zeros(3)
        for j, mat in enumerate(self.media):
            sel = np.flatnonzero(where == j)
            if sel.size == 0:
                continue
            depths, strengths = np.zeros((3, 6)), np.zeros((3, 6))
            for c in range(3):
                x, q = line_rule(float(mat.albedo_prime[c]))
                depths[c] = x / float(mat.sigma_t_prime[c])
                strengths[c] = q * ewald_weight(float(mat.medium.kappa[c]), spread)
            idx = slice(None) if sel.size == len(samples) else sel
            lc, dc = lattice_loads(lattice, samples.positions[idx], w[idx], samples.normals[idx],
                                   samples.power[idx], depths, strengths, spread)
            loads = lc if loads is None else loads + lc
            dropped = dropped + dc
        if loads is None:
            loads = np.zeros((lattice.n_nodes, 3))
        return loads, dropped

    def near_field(self, src, rec, spacing_mm):
        if len(self.media) == 1:
            return remainder_exitance(self.tables_at[0], src, rec, spacing_mm=spacing_mm)
        # each receiver in its own medium's table, each entry's power in its own (eq. (134))
        return remainder_exitance(self.tables_at, src, rec, spacing_mm=spacing_mm,
                                  blend=_one_corner(self.sample_medium), src_blend=self._src_blend(src))

    def point_near_field(self, src, rec, points):
        if len(self.media) == 1:
            return remainder_exitance(self.tables_at[0], src, rec)[0]
        _, i = self._tree.query(np.asarray(points, dtype=np.float64))
        return remainder_exitance(self.tables_at, src, rec, blend=_one_corner(self.sample_medium[i]),
                                  src_blend=self._src_blend(src))[0]


def _one_corner(medium):
    """(tables (n, 3, 1), weights (n, 3, 1)): each point's own medium's table, weight 1."""
    n = len(medium)
    return np.broadcast_to(np.asarray(medium, dtype=np.int64)[:, None, None], (n, 3, 1)).copy(), np.ones((n, 3, 1))
