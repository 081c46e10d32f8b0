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
from meshshade.materials import Material
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
        self._digest = hashlib.sha1(self.face_part.tobytes()).hexdigest()[:12]

    @property
    def n_parts(self) -> int:
        return len(self.materials)

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
        innermost of the parts whose own winding number there is above 1/2 in magnitude), or -1 where none is."""
        P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        out = np.full(P.shape[0], -1, dtype=np.int64)
        if self._trees is None or self._trees[0] is not faces:
            trees = [TriangleTree(vertices, self.faces_of(k, faces)) for k in range(self.n_parts)]
            self._trees = (faces, trees, self.enclosed_volumes(vertices, faces))
        _, trees, vol = self._trees
        best = np.full(P.shape[0], np.inf)
        for k in np.argsort(vol, kind="stable")[::-1]:      # largest first: an inner part overwrites
            inside = np.abs(trees[k].winding(P)) > 0.5     # a nested part may be wound inward (below)
            take = inside & (vol[k] <= best)
            out[take] = k
            best[take] = vol[k]
        return out
