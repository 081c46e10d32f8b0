"""Parts of different media: a mesh whose faces belong to named parts, each part its own material
(docs/physics.md §17).

A part is the region where the generalised winding number of its own faces is above 1/2 in magnitude (Jacobson, Kavan &
Sorkine-Hornung 2013): a closed part is its inside, an open one the inside its winding number says. Where parts
nest or overlap, the innermost owns a point: of the parts whose winding number there is above 1/2, the one that
encloses the least volume (:meth:`PartedMaterial.part_at`). The winding number's magnitude is what counts: a
closed part nested in another is a cavity to the mesh's orientation repair
(:func:`meshshade.geometry.mesh.validate_mesh` turns it inward, so its own winding number is -1 inside it), and it is
still that part. The interfaces between parts are index-matched: light
crosses them unrefracted and unreflected; only the object's boundary (the boundary of the union of the parts) has a
Fresnel interface, with the index of the part inside it there.

:class:`PartedMaterial` is a record: the parts' materials, their names and the part of each input face. It is made
where the parts are read (the CLI's ``--material NAME=PRESET``, a job file, the add-on) and read by the volume, the
near field and the Monte Carlo.
"""
from __future__ import annotations

import hashlib

import numpy as np

from meshshade.errors import MaterialError
from meshshade.geometry.mesh import Mesh
from meshshade.materials import Material
from meshshade.volume.inside import WINDING_EXACT, WINDING_FAST, WINDING_MARGIN
from meshshade.volume.triangle_tree import TriangleTree

__all__ = ["PartedMaterial"]


class PartedMaterial:
    """``materials`` (one :class:`~meshshade.materials.Material` per part), ``names`` (one per part, unique) and
    ``face_part`` (m,) int, the part of each of the mesh's faces, in ``range(len(materials))``."""

    def __init__(self, materials, face_part, names=None, *, name: str | None = None):
        materials = tuple(materials)
        if not materials:
            raise MaterialError("a material of parts needs at least one part")
        for m in materials:
            if not isinstance(m, Material):
                raise MaterialError(f"each part's material must be a Material, got {type(m).__name__}")
        names = tuple(str(n) for n in (names if names is not None else (m.name for m in materials)))
        if len(names) != len(materials):
            raise MaterialError(f"{len(names)} part names for {len(materials)} parts")
        if len(set(names)) != len(names):
            raise MaterialError(f"part names must be unique, got {', '.join(names)}")
        fp = np.asarray(face_part)
        if fp.ndim != 1 or not np.issubdtype(fp.dtype, np.integer):
            raise MaterialError(f"face_part must be a 1-D integer array, got {fp.dtype} of shape {fp.shape}")
        if fp.size and (fp.min() < 0 or fp.max() >= len(materials)):
            raise MaterialError(f"face_part names parts outside 0..{len(materials) - 1}")
        self.materials = materials
        self.names = names
        self.face_part = np.ascontiguousarray(fp, dtype=np.int64)
        self.name = name or " + ".join(f"{n}={m.name}" for n, m in zip(names, materials))
        self._trees = None
        self._oriented = None
        self._digest = hashlib.sha1(self.face_part.tobytes()).hexdigest()[:12]

    @classmethod
    def from_names(cls, face_names: dict, assignments, default=None, *, where: str = "the mesh"):
        """The parts ``assignments`` ((name, Material) pairs, in order) name among ``face_names`` (name -> (m,)
        bool: the faces a mesh file gives that name, :func:`meshshade.io.part_names.read_face_names`), every other
        face one part of ``default``. A face two assignments name takes the later one. MaterialError (one line)
        for a name no face has (listing the names ``where`` has), for faces left without a material when
        ``default`` is None, or for an assignment that leaves a part without faces."""
        names = list(face_names)
        if not names and assignments:
            raise MaterialError(f"{where} names no parts (an OBJ's usemtl or g names, a glTF's materials), so "
                                f"{assignments[0][0]}=... matches nothing")
        n = len(next(iter(face_names.values()))) if names else 0
        part = np.full(n, -1, dtype=np.int64)
        materials, part_names = [], []
        for name, material in assignments:
            if name not in face_names:
                raise MaterialError(f"no part named {name!r} in {where}; it has: {', '.join(names)}")
            if name in part_names:
                raise MaterialError(f"part {name!r} is given a material twice")
            part[face_names[name]] = len(materials)
            materials.append(material)
            part_names.append(name)
        rest = part < 0
        if rest.any():
            if default is None:
                raise MaterialError(f"{int(rest.sum())} faces of {where} are in none of the parts named "
                                    f"({', '.join(part_names)}): give a material for the rest too (--material NAME)")
            part[rest] = len(materials)
            materials.append(default)
            part_names.append("rest" if "rest" not in part_names else "rest_")
        used = np.bincount(part, minlength=len(materials))
        if np.any(used == 0):
            empty = [part_names[i] for i in np.flatnonzero(used == 0)]
            raise MaterialError(f"the parts {', '.join(empty)} keep no faces (a later part takes them all)")
        return cls(materials, part, part_names)

    @property
    def n_parts(self) -> int:
        return len(self.materials)

    @property
    def eta(self) -> float:
        """The parts' one index (:meth:`check_one_index`; the internal interfaces are index-matched)."""
        self.check_one_index()
        return self.materials[0].eta

    def check_one_index(self) -> None:
        """MaterialError unless every part has the same index (the interfaces between parts are index-matched:
        light crosses them unrefracted, which only one index on both sides is; docs/physics.md §17 "Parts")."""
        etas = sorted({float(m.eta) for m in self.materials})
        if len(etas) > 1:
            raise MaterialError(f"the parts' materials have different indices ({', '.join(f'{e:g}' for e in etas)});"
                                " the interfaces between parts are index-matched, so the parts need one index")

    @property
    def is_single(self) -> bool:
        """Whether every part has the same material (then the mesh is of one medium)."""
        return all(m == self.materials[0] for m in self.materials[1:])

    def describe(self) -> str:
        return "; ".join(f"{n}: {m.describe()}" for n, m in zip(self.names, self.materials)) + f" ({self._digest})"

    def to_dict(self) -> dict:
        return {"name": self.name, "parts": {n: m.to_dict() for n, m in zip(self.names, self.materials)}}

    def check_mesh(self, mesh) -> None:
        """MaterialError unless the parts fit ``mesh``: a part for each of its faces."""
        if self.face_part.shape[0] != mesh.n_faces:
            raise MaterialError(f"the parts name {self.face_part.shape[0]} faces, the mesh has {mesh.n_faces}")

    def oriented(self, mesh):
        """``mesh`` with each part's faces turned outward as a solid of its own (its enclosed volume positive):
        a part nested in another is a solid inside it, not a cavity, though the mesh's own repair
        (:func:`meshshade.geometry.topology.orient_outward`) counts a closed surface inside another as a cavity's
        wall and turns it inward (and two parts touching along a face, each inside the other there, both).
        The same Mesh where nothing turns; kept per mesh, so a bake of it is reused."""
        self.check_mesh(mesh)
        if self._oriented is not None and self._oriented[0] is mesh:
            return self._oriented[1]
        V, F = mesh.vertices, np.array(mesh.faces, dtype=np.int64)
        det = np.einsum("ij,ij->i", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]]))
        vol = np.bincount(self.face_part, weights=det, minlength=self.n_parts)
        flip = (vol < 0)[self.face_part]
        out = mesh
        if flip.any():
            F[flip] = F[flip][:, [0, 2, 1]]
            out = Mesh(V, F, mm_per_unit=mesh.mm_per_unit, source=mesh.source, defects=mesh.defects)
        self._oriented = (mesh, out)
        return out

    def faces_of(self, k: int, faces) -> np.ndarray:
        """(f_k, 3) the faces of part ``k`` among the mesh's ``faces`` (m, 3)."""
        return np.asarray(faces)[self.face_part == k]

    def enclosed_volumes(self, vertices, faces) -> np.ndarray:
        """(n_parts,) mm^3: the volume each part's faces enclose (|divergence theorem|; an open part's the cone
        volume of its faces from the origin, a measure of size that orders nested parts)."""
        V = np.asarray(vertices, dtype=np.float64)
        F = np.asarray(faces, dtype=np.int64)
        det = np.einsum("ij,ij->i", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]])) / 6.0
        return np.abs(np.bincount(self.face_part, weights=det, minlength=self.n_parts))

    def outward_faces(self, vertices, faces) -> tuple[np.ndarray, np.ndarray]:
        """((m, 3) faces, (m,) bool turned): ``faces`` with each part wound so that its own signed enclosed volume
        is >= 0 (a nested part that the mesh's orientation repair turned inward as a cavity, turned back), so that
        the winding number of all the faces is above 1/2 in the union of the parts (the medium the Monte Carlo
        walks in) and the faces between parts have it on both sides."""
        V = np.asarray(vertices, dtype=np.float64)
        F = np.array(faces, dtype=np.int64, copy=True)
        det = np.einsum("ij,ij->i", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]]))
        signed = np.bincount(self.face_part, weights=det, minlength=self.n_parts)
        turned = signed[self.face_part] < 0
        F[turned] = F[turned][:, [0, 2, 1]]
        return F, turned

    def part_at(self, vertices, faces, points) -> np.ndarray:
        """(p,) int: the part owning each of ``points`` (p, 3) mm on the mesh of ``vertices`` and ``faces`` (the
        innermost of the parts whose own winding number there is above 1/2 in magnitude: a nested part that the
        mesh's orientation repair wound inward is still that part), or -1 where none is. A part's winding number is
        asked only inside its faces' bounding box (outside it a surface subtends less than a half sphere:
        |w| < 1/2), quickly first and exactly where that is near 1/2 (as the volume's inside,
        :meth:`meshshade.volume.inside.SurfaceVolume.winding`)."""
        P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        out = np.full(P.shape[0], -1, dtype=np.int64)
        if self._trees is None or self._trees[0] is not faces:
            V = np.asarray(vertices, dtype=np.float64)
            parts = [self.faces_of(k, faces) for k in range(self.n_parts)]
            trees = [TriangleTree(V, f) if len(f) else None for f in parts]
            boxes = [(V[f].reshape(-1, 3).min(axis=0), V[f].reshape(-1, 3).max(axis=0)) if len(f) else None
                     for f in parts]
            self._trees = (faces, trees, boxes, self.enclosed_volumes(vertices, faces))
        _, trees, boxes, vol = self._trees
        best = np.full(P.shape[0], np.inf)
        for k in np.argsort(vol, kind="stable")[::-1]:      # largest first: an inner part overwrites
            if trees[k] is None:
                continue
            lo, hi = boxes[k]
            ask = np.flatnonzero(np.all((P >= lo) & (P <= hi), axis=1))
            if ask.size == 0:
                continue
            w = np.abs(trees[k].winding(P[ask], WINDING_FAST))      # a nested part may be wound inward
            unsure = np.flatnonzero(np.abs(w - 0.5) < WINDING_MARGIN)
            if unsure.size:
                w[unsure] = np.abs(trees[k].winding(P[ask[unsure]], WINDING_EXACT))
            take = ask[(w > 0.5) & (vol[k] <= best[ask])]
            out[take] = k
            best[take] = vol[k]
        return out
