"""The scenes of `meshshade bench` as data: geometry, size, light, reference kind and default resolution.

Spheres of R0 = 5, 20 and 100 mm, a long cylinder and a torus (procedural, refined by level), and two real
meshes of ../shared/meshes at realistic sizes, each under a beam or a directional light. The material is the
skin-like grey medium of docs/physics.md §11 (sigma_s' = 1, sigma_a = 0.01 /mm, eta = 1.3); errors are taken on
channel 0.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshshade.errors import ParameterError
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import capped_cylinder, icosphere, torus
from meshshade.io import read_mesh_arrays
from meshshade.light import BeamLight, DirectionalLight
from meshshade.materials import Material

MATERIAL = Material(1.0, 0.01, 1.3, name="skin-like")


def shared_meshes_dir() -> Path:
    """../shared/meshes next to the project (or $MESHSHADE_SHARED/meshes), as tests/conftest.py finds it."""
    root = Path(__file__).resolve().parents[3] / "shared"
    return Path(os.environ.get("MESHSHADE_SHARED", root)) / "meshes"


@dataclass(frozen=True)
class Scene:
    """A benchmark scene as data: geometry, size, light, reference kind and default resolution.

    shape : "sphere" (radius ``size_mm``) | "cylinder" (radius ``size_mm``, length ``length_mm``, along z) |
        "torus" (tube radius ``size_mm``, major radius 3 x size) | "mesh" (``mesh_file`` in ../shared/meshes,
        centred, largest extent scaled to ``size_mm``)
    light : "beam" | "directional"; reference : "exact" | "mc"; level : default refinement;
    geodesic : the scene's baseline geodesic method; patch_mm : MC comparison patch size
    """

    name: str
    shape: str
    size_mm: float
    light: str
    reference: str
    level: int = 4
    length_mm: float = 100.0
    mesh_file: str | None = None
    geodesic: str = "exact"
    patch_mm: float = 2.0

    def build(self, level: int | None = None) -> Mesh:
        """The scene's mesh (mm) at refinement ``level`` (default: the scene's)."""
        L = self.level if level is None else int(level)
        R = self.size_mm
        if self.shape == "sphere":
            V, F = icosphere(R, L)
        elif self.shape == "cylinder":
            seg = 2 ** (L + 2)
            V, F = capped_cylinder(R, self.length_mm, seg, int(round(self.length_mm / (2 * np.pi * R / seg))))
        elif self.shape == "torus":
            V, F = torus(3.0 * R, R, 3 * 2 ** (L + 2), 2 ** (L + 2))
        elif self.shape == "mesh":
            path = shared_meshes_dir() / self.mesh_file
            if not path.exists():
                raise ParameterError(f"scene {self.name}: {path} not found (../shared/meshes is only in the "
                                     "developers' workspace)")
            V, F = read_mesh_arrays(path)
            V = (V - 0.5 * (V.min(axis=0) + V.max(axis=0))) * (self.size_mm / np.ptp(V, axis=0).max())
        else:
            raise ParameterError(f"unknown scene shape {self.shape!r}")
        return Mesh.from_arrays(V, F, source=f"bench:{self.name}:L{L}")

    def make_light(self, mesh):
        """The scene's light, aimed from outside: beams with small offsets so they never hit a vertex."""
        R = self.size_mm
        if self.light == "directional":
            d = (0.0, 0.0, -1.0) if self.shape == "sphere" else (0.3, -0.4, -0.866)
            return DirectionalLight(d, 1.0)
        if self.shape == "sphere":
            return BeamLight((0.0123 * R, 0.0071 * R, 3.0 * R), (0.0, 0.0, -1.0))
        if self.shape == "cylinder":
            return BeamLight((3.0 * R, 0.0131 * R, 0.0213 * R), (-1.0, 0.0, 0.0))
        if self.shape == "torus":  # from the hole's centre outwards: enters at the inner equator, a saddle
            return BeamLight((0.0, 0.0131, 0.0213), (1.0, 0.0, 0.0))
        c = mesh.bbox.mean(axis=0)
        return BeamLight((c[0] + 0.0131, c[1] + 0.0213, mesh.bbox[1, 2] + 0.5 * self.size_mm), (0.0, 0.0, -1.0))

    @property
    def procedural(self) -> bool:
        return self.shape != "mesh"


def _s(name, shape, size, light, ref, **kw):
    return Scene(name, shape, size, light, ref, **kw)


#: every scene of the full run (quick mode picks some and coarsens them, see bench_plan)
SCENES = {s.name: s for s in (
    _s("sphere_r5_beam", "sphere", 5.0, "beam", "exact", level=5),
    _s("sphere_r20_beam", "sphere", 20.0, "beam", "exact", level=5),
    _s("sphere_r100_beam", "sphere", 100.0, "beam", "exact", level=6),
    _s("sphere_r5_directional", "sphere", 5.0, "directional", "exact", level=3, geodesic="arc"),
    _s("sphere_r20_directional", "sphere", 20.0, "directional", "exact", level=4, geodesic="arc"),
    _s("sphere_r100_directional", "sphere", 100.0, "directional", "exact", level=4, geodesic="arc"),
    _s("cylinder_r10_beam", "cylinder", 10.0, "beam", "exact", level=4, length_mm=100.0),
    _s("torus_beam", "torus", 10.0, "beam", "mc", level=4, patch_mm=1.5),
    _s("torus_directional", "torus", 10.0, "directional", "mc", level=3, geodesic="arc", patch_mm=3.0),
    _s("spot_50mm_beam", "mesh", 50.0, "beam", "mc", mesh_file="spot.obj", patch_mm=1.5),
    _s("head_200mm_beam", "mesh", 200.0, "beam", "mc", mesh_file="lee_perry_smith_head.obj", patch_mm=2.0),
    _s("head_200mm_directional", "mesh", 200.0, "directional", "mc", mesh_file="lee_perry_smith_head.obj",
       patch_mm=6.0),
    _s("spot_50mm_directional", "mesh", 50.0, "directional", "mc", mesh_file="spot.obj", patch_mm=2.0),
)}
