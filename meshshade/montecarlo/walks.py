"""The walks of one Monte Carlo run: what they need (:class:`WalkSetup`), one channel group's walk over a range of
entry chunks (:func:`walk_group`) and its per-batch tallies (:class:`GroupTally`, which add up).

:func:`meshshade.montecarlo.simulation.simulate` walks every group over all its photons in this process;
:mod:`meshshade.montecarlo.distributed` walks ranges of entry chunks on Dask workers and adds the tallies. Photon
``i`` of group ``k`` draws its entry and every random number of its walk from streams keyed by (seed, k, i)
(:mod:`meshshade.montecarlo.emission`, :mod:`meshshade.montecarlo.engine`), so a range of entry chunks
(``ENTRY_CHUNK`` photons each, the unit of the split) walked anywhere gives the photons the whole run would give
them.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from meshshade.errors import MeshshadeError
from meshshade.geometry.mesh import MeshDefectWarning
from meshshade.materials import Material
from meshshade.montecarlo.boundary import WalkSurface, walk_surface
from meshshade.montecarlo.emitter import Emitter
from meshshade.montecarlo.engine import PoolWalk
from meshshade.montecarlo.interior import SafeDistanceGrid, open_surface_warning
from meshshade.montecarlo.sampling import GroupMedium
from meshshade.montecarlo.wavefront_oracle import WavefrontWalk
from meshshade.raycast import make_scene
from meshshade.raycast.embree_direct import DirectEmbreeScene

__all__ = ["ENGINES", "WalkSetup", "GroupTally", "channel_groups", "check_engine", "make_emitter", "prepare_walks",
           "walk_group"]

#: the pooled engine's ways of calling Embree: "fused" (rtcIntersect1 from the numba threads, inside the walk),
#: "batched" (one embreex call per round), "auto" (fused when the Embree library can be bound)
ENGINES = ("auto", "fused", "batched")


def check_engine(engine, stacklevel: int = 3) -> str:
    """``engine`` if it is one of :data:`ENGINES`; "direct", its former spelling of "fused", with a
    DeprecationWarning (attributed ``stacklevel`` frames up); MeshshadeError otherwise."""
    if engine == "direct":
        warnings.warn("engine='direct' is deprecated; use engine='fused'", DeprecationWarning, stacklevel=stacklevel)
        return "fused"
    if engine not in ENGINES:
        raise MeshshadeError(f"engine must be 'auto', 'fused' or 'batched', got {engine!r}")
    return engine


def channel_groups(material: Material) -> list[tuple[tuple[float, float], list[int]]]:
    """``[((sigma_s, sigma_a), [channels]), ...]``: one walk per distinct pair of the material's medium (the real
    scattering coefficient sigma_s = sigma_s' / (1 - g) and the absorption, 1/mm), in channel order."""
    m = material.medium
    groups: dict = {}
    for c in range(3):
        groups.setdefault((float(m.sigma_s[c]), float(m.sigma_a[c])), []).append(c)
    return list(groups.items())


@dataclass
class WalkSetup:
    """Everything the walks of one (mesh, lights, material) need besides the photons: the walk surface's arrays
    (:class:`~meshshade.montecarlo.boundary.WalkSurface`: the mesh's boundary faces and the lids of its holes; the
    mesh itself when it is closed), its Embree scene, the safe-distance grid (pooled engine), the direct Embree
    binding (or None) and the emitter."""

    V: np.ndarray
    F: np.ndarray
    normals: np.ndarray
    scene: object
    grid: object
    direct: object
    emitter: Emitter
    material: Material
    groups: list
    fast_interior: bool
    surface: WalkSurface | None = None


def surface_note(surface: WalkSurface) -> str | None:
    """The one line a run on ``surface`` warns with: what the walk does beyond the mesh's faces (lids,
    transparent faces), or, where the walk is the mesh's faces alone, what it does at an open edge (None for a
    closed mesh)."""
    return open_surface_warning(surface.faces) if surface.identity else surface.describe()


def make_emitter(mesh, surface: WalkSurface, lights, eta, scene) -> Emitter:
    """The emitter of a walk on ``surface`` (``scene`` its Embree scene): photons enter the walk surface (a lid
    too), and which lights reach is decided on ``mesh`` as the bake decides it."""
    bake_mesh = None
    if not surface.identity:
        bake_mesh = (mesh.vertices, mesh.faces, mesh.face_normals, mesh.face_areas,
                     make_scene(mesh.vertices, mesh.faces), surface.walk_face, surface.flipped)
    return Emitter(surface.vertices, surface.faces, surface.normals, surface.areas, lights, scene, eta,
                   bake_mesh=bake_mesh)


def prepare_walks(mesh, material: Material, lights, *, engine: str = "auto", fast_interior: bool = True,
                  half_space_certificates: bool = True, stacklevel: int = 3,
                  surface: WalkSurface | None = None) -> WalkSetup:
    """Build the walk surface, scene, grid and emitter of a run (the set-up :func:`simulate` does before its first
    photon).

    half_space_certificates : also certify free paths inside local half-spaces (a set-up cost that pays back
        except under a short time budget).
    surface : the :class:`~meshshade.montecarlo.boundary.WalkSurface` to walk in (default
        :func:`~meshshade.montecarlo.boundary.walk_surface` of ``mesh``: the bake's inside {w > 1/2}).
    """
    engine = check_engine(engine)
    surface = walk_surface(mesh) if surface is None else surface
    if msg := surface_note(surface):
        warnings.warn(msg, MeshDefectWarning, stacklevel=stacklevel)
    V, F = surface.vertices, surface.faces
    scene = make_scene(V, F)
    grid = direct = None
    if fast_interior:
        sigma_t_max = float(np.max(material.medium.sigma_s + material.medium.sigma_a))
        use_planes = sigma_t_max > 0 and half_space_certificates
        grid = SafeDistanceGrid(V, F, mean_free_path=1.0 / sigma_t_max if use_planes else None)
        if engine != "batched" and getattr(scene, "backend", "") == "embree":
            try:
                direct = DirectEmbreeScene(V, F, scene.center)
            except (RuntimeError, OSError) as exc:
                if engine == "fused":
                    raise MeshshadeError(f"engine='fused' is not available here ({exc}); use 'batched'") from exc
    emitter = make_emitter(mesh, surface, lights, material.eta, scene)
    return WalkSetup(V, F, surface.normals, scene, grid, direct, emitter, material, channel_groups(material),
                     fast_interior, surface)


@dataclass
class GroupTally:
    """Per-batch tallies of one channel group's walk (W): ``face`` (B, m), ``face_vert`` (B, n), ``tot`` (B, 7)
    (specular, diffuse, transmitted, absorbed, lost, incident, entering), counts, and the exits of the first beam's
    photons (lists of arrays ``face``, ``bary``, ``weight``, ``batch``). ``a + b`` is the tally of both walks."""

    face: np.ndarray
    face_vert: np.ndarray
    tot: np.ndarray
    emitted: int = 0
    events: int = 0
    boundary: int = 0
    rays: int = 0
    exits: dict = field(default_factory=lambda: {"face": [], "bary": [], "weight": [], "batch": []})

    def __add__(self, other: "GroupTally") -> "GroupTally":
        return GroupTally(self.face + other.face, self.face_vert + other.face_vert, self.tot + other.tot,
                          self.emitted + other.emitted, self.events + other.events, self.boundary + other.boundary,
                          self.rays + other.rays, {k: self.exits[k] + other.exits[k] for k in self.exits})


def walk_group(setup: WalkSetup, gi: int, n_photons: int, *, seed: int, n_batches: int, pool: int | None,
               keep_beam: bool, time_budget: float | None = None, progress=None, chunks=None,
               rng=None) -> GroupTally:
    """Walk channel group ``gi`` of ``setup`` (photons of entry chunks ``chunks=(c0, c1)``, default all, of a run
    of ``n_photons``); weights are those of the whole run (P / n_photons). ``rng``: the baseline wavefront's
    generator (``fast_interior=False``, which walks whole runs only)."""
    (ss, sa), _chans = setup.groups[gi]
    m = setup.material
    medium = GroupMedium(ss, sa, m.g, m.eta)
    common = dict(n_batches=n_batches, keep_beam=keep_beam)
    if setup.fast_interior:
        walk = PoolWalk(setup.V, setup.F, setup.normals, setup.emitter, setup.scene, setup.grid, medium, seed=seed,
                        group=gi, direct=setup.direct, **common)
        emitted = walk.run(n_photons, pool=pool, time_budget=time_budget, progress=progress, chunks=chunks)
    else:
        if chunks is not None:
            raise MeshshadeError("the baseline wavefront (fast_interior=False) walks whole runs only")
        walk = WavefrontWalk(setup.V, setup.F, setup.normals, setup.emitter, setup.scene, medium, **common)
        emitted = walk.run(n_photons, rng, pool=pool or 1 << 16, time_budget=time_budget, progress=progress)
    return GroupTally(walk.face, walk.face_vert, walk.tot, int(emitted), int(walk.events), int(walk.boundary),
                      int(walk.rays), {k: list(v) for k, v in walk.exits.items()})
