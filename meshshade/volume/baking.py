"""The volume model's bake (the default): the transport kept for the mesh and material, the lights' entry samples on
the surface it samples, then its exitance (:class:`meshshade.volume.transport.VolumeTransport`, docs/physics.md
§15).

:func:`meshshade.transport.bake` runs :class:`VolumeModel` for ``model="volume"`` and makes its result of what
:meth:`VolumeModel.run` returns (:class:`VolumeBake`); a mesh that encloses nothing the lattice resolves answers
None with the reason, and the bake falls back to a surface model.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from meshshade import memo
from meshshade.errors import NoVolumeError
from meshshade.light import entry_samples
from meshshade.progress import Progress
from meshshade.raycast import make_scene
from meshshade.volume.transport import VolumeTransport

__all__ = ["VolumeModel", "VolumeBake", "VOLUME_STAGES"]

#: the volume bake's stages in order, with their rough shares of its time (the progress bar's units)
VOLUME_STAGES = {"volume sampling": 1, "near-field tables": 1, "rays": 1, "volume lattice": 3, "volume operator": 2,
                 "volume multigrid": 2, "volume sources": 1, "volume solve": 3, "near field": 3, "uncollided": 1}


class VolumeBake(NamedTuple):
    """What :meth:`VolumeModel.run` returns: ``radiance`` (n, 3) W/mm^2 at the mesh's vertices, the ``samples``
    (EntrySamples), ``cutoff_mm`` (3,) (the near field's reach), ``stats``, the ``transport`` (VolumeTransport,
    for reuse) and ``sample_radiance`` (n_s, 3), the solution on the surface it samples."""

    radiance: np.ndarray
    samples: object
    cutoff_mm: np.ndarray
    stats: dict
    transport: VolumeTransport
    sample_radiance: np.ndarray


class VolumeModel:
    """The volume transport as a model of :func:`meshshade.transport.bake` (module docstring)."""

    name = "volume"

    def run(self, mesh, material, lights, options, clock, reuse=None):
        """``(VolumeBake or None, why not)``: the exitance of ``mesh`` in ``material`` under ``lights`` (a list) with
        the bake's ``options`` (:class:`~meshshade.transport.options.BakeOptions`; its ``volume`` record), stages
        charged to ``clock``; ``reuse``: a VolumeTransport an earlier bake built for this mesh and material. None
        where the mesh encloses no volume the lattice resolves (a flat sheet: a
        :class:`~meshshade.errors.NoVolumeError` at the build or at the first light)."""
        bar, on_stage = _progress(options.progress)
        try:
            vt, why = (reuse, None) if reuse is not None else _transport(mesh, material, options, clock, on_stage)
            if vt is None:
                return None, why
            vt.on_stage = on_stage
            try:
                return _exitance(vt, lights, options.backend, clock, on_stage), None
            except NoVolumeError as e:     # found when the lattice is built for the light: nothing inside
                return None, f"the volume transport cannot be built ({str(e).splitlines()[0]})"
            finally:
                vt.on_stage = None
        finally:
            if bar is not None:
                bar.close()


def _progress(progress):
    """(Progress or None, on_stage callback or None) of a volume bake: a bar over its stages, named as they run."""
    if not progress:
        return None, None
    bar = Progress(progress if isinstance(progress, str) else "bake", sum(VOLUME_STAGES.values()), "")
    order = list(VOLUME_STAGES)
    bar.set_stage(order[0])

    def on_stage(name):                                   # ``name`` has ended: the next one runs now
        if name in order and order.index(name) + 1 < len(order):
            bar.set_stage(order[order.index(name) + 1])
        bar.update(VOLUME_STAGES.get(name, 0))
    return bar, on_stage


def _transport(mesh, material, options, clock, on_stage=None):
    """``(VolumeTransport or None, why not)``: kept for this mesh, material and volume options inside
    :func:`meshshade.memo.reuse`, or a new one."""
    built = []

    def build():
        built.append(True)
        try:
            return VolumeTransport.build(mesh, material, options.volume, on_stage=on_stage), None
        except NoVolumeError as e:
            return None, f"the volume transport cannot be built ({str(e).splitlines()[0]})"

    vt, why = memo.cached("volume", (id(mesh), material.describe(), options.volume), build, pins=(mesh,))
    if vt is not None and built:
        clock.charge(vt.timings)
    return vt, why


def _exitance(vt, lights, backend, clock, on_stage=None) -> VolumeBake:
    """The volume transport ``vt``'s exitance under ``lights``: entry samples on the surface it samples (Embree
    rays), the solve and the near field, read at the mesh's vertices."""
    S = vt.surface.samples
    scene = memo.cached("scene", (id(S), backend), lambda: make_scene(S.vertices, S.faces, backend=backend),
                        pins=(S,))
    samples = entry_samples(S.vertices, S.faces, S.vertex_normals, S.vertex_areas, lights, scene=scene,
                            eta=vt.material.eta)
    clock.lap("rays")
    if on_stage is not None:
        on_stage("rays")
    Ms, vstats = vt.sample_exitance(samples, scene)
    clock.charge(vstats.pop("timings"))
    stats = {"entry_samples": len(samples), "cutoff_mm": vt.tables.radius_mm.tolist(), **samples.stats,
             **vt.stats, **vstats, "transport": "volume", "near_field": "beam"}
    return VolumeBake(vt.to_vertices(Ms), samples, vt.tables.radius_mm.copy(), stats, vt, Ms)
