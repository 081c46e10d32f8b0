"""The bake's result: :class:`BakeResult` (per-vertex exitance, where the light entered, what each stage took) and
the one-line descriptions the CLI prints (:func:`describe_scale`, :func:`describe_result`, :func:`mesh_note`); the
same record whichever transport made it."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from meshshade.materials import Material
from meshshade.preview import mesh_preview

__all__ = ["BakeResult", "describe_scale", "describe_result", "mesh_note"]


@dataclass(frozen=True)
class BakeResult:
    """Per-vertex result of :func:`bake`.

    radiance : (n, 3) float64 W/mm^2 — linear radiant exitance per channel (r, g, b)
    k1, k2 : (n,) 1/mm; d1, d2 : (n, 3) — principal curvatures and directions of the mesh (None for the volume
                model, which needs none)
    samples : EntrySamples — where light entered and how much
    beam_distance : (n,) mm or None — geodesic distance of each vertex from the first beam's entry point
                    (inf beyond the neighbourhood)
    cutoff_mm : (3,) — neighbourhood radius per channel
    timings : dict stage -> seconds; stats : dict of counts (pairs, skipped work, fallbacks, auto decisions)
    plan : meshshade.surface.auto.AutoPlan or None — the per-sample decisions of ``model="auto"``
    volume : meshshade.volume.transport.VolumeTransport or None — the volume transport of ``model="volume"``
             (reuse it for further lights: ``bake(..., reuse=result.volume)``; per-pixel renders use its near field)
    sample_exitance : (n_s, 3) W/mm^2 or None — the volume model's solution at the vertices of the surface it
             samples (``volume.surface``; P1 between them), which textures and per-pixel renders interpolate
    """

    radiance: np.ndarray
    k1: np.ndarray
    k2: np.ndarray
    d1: np.ndarray
    d2: np.ndarray
    samples: object
    beam_distance: np.ndarray | None
    cutoff_mm: np.ndarray
    model: str
    material: Material
    timings: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    plan: object = None
    volume: object = None
    sample_exitance: np.ndarray | None = None

    def patch_averaged(self) -> np.ndarray:
        """(n, 3) W/mm^2: the exitance averaged over each vertex's patch with the vertex's hat function (eq. (104)),
        which is what the in-mesh Monte Carlo tallies at a vertex (:func:`meshshade.montecarlo.simulate`): the
        quantity to compare with it. ``radiance`` is the field's value at the vertex (what textures and renders read
        there too); the surface models, which have no field between vertices, give ``radiance`` itself."""
        if self.volume is None or self.sample_exitance is None:
            return self.radiance
        out = np.array(self.volume.surface.patch_average(self.sample_exitance), dtype=np.float64)
        out[self.volume.buried] = 0.0
        return out

    def __repr__(self) -> str:
        n = self.radiance.shape[0]
        peak = self.radiance.max(axis=0)
        total = sum(self.timings.values())
        transport = str(self.stats.get("transport", "")).split(" (")[0]
        return (f"<BakeResult {self.model}, {self.material.name}: {n} vertices, {len(self.samples)} entry samples"
                + (f", {transport} transport" if transport else "")
                + f"; peak exitance {peak[0]:.4g}/{peak[1]:.4g}/{peak[2]:.4g} W/mm^2 (r/g/b); {total:.3g} s>")

    def plot(self, mesh, **kwargs):
        """A matplotlib figure of ``mesh`` (the mesh that was baked) coloured by the exitance
        (:func:`meshshade.preview.mesh_preview`; keyword arguments go there)."""
        kwargs.setdefault("title", f"{self.model}, {self.material.name}")
        return mesh_preview(mesh.vertices, mesh.faces, self.radiance, **kwargs)


def describe_scale(mesh, material: Material) -> str:
    """One line: mesh size in mm and in transport mean free paths (per channel), so unit mistakes show."""
    size = mesh.bbox_size_mm
    mfp = size.max() * material.sigma_t_prime
    return (f"mesh: {mesh.n_vertices} vertices, {mesh.n_faces} faces, {size[0]:.4g} x {size[1]:.4g} x "
            f"{size[2]:.4g} mm (largest extent = {mfp[0]:.4g}/{mfp[1]:.4g}/{mfp[2]:.4g} transport mean free "
            f"paths r/g/b; mean edge {mesh.mean_edge_length:.4g} mm); material {material.describe()}")


def mesh_note(result: BakeResult) -> str | None:
    """One line on what the bake made of a mesh that is not one closed part (None for one closed part): the
    volume over an open or many-part mesh, buried vertices, or why the surface transport was used instead."""
    s = result.stats
    if s.get("transport") == "volume":
        closed, parts = s.get("volume_closed", True), s.get("volume_parts", 1)
        buried = s.get("volume_buried_vertices", 0)
        if closed and parts <= 1 and not buried:
            return None
        what = [] if closed else ["holes closed by the winding number"]
        if parts > 1:
            what.append(f"{parts} parts baked as their union (overlapping parts share light)")
        if buried:
            what.append(f"{buried} vertices buried inside other parts report 0")
        return "volume transport on " + ("a closed" if closed else "an open") + " mesh: " + "; ".join(what)
    why = str(s.get("transport", ""))
    if "[volume transport not used:" in why:
        return "surface transport: " + why.split("[volume transport not used:", 1)[1].rstrip("]").strip()
    return None


def describe_result(result: BakeResult) -> str:
    """One line: entry samples, pairs, far field and zones, entering and exitant power, timings."""
    s = result.stats
    t = ", ".join(f"{k} {v:.3g} s" for k, v in result.timings.items())
    ex = s["exitant_power"]
    if s.get("transport") == "volume":
        cells = s.get("volume_cells_per_level", [])
        why = s.get("volume_resolution_reason", s["volume_resolution_limited_by"])
        return (f"volume: {s['entry_samples']} entry samples; diffusion on {sum(cells)} cubes of "
                f"{s['volume_resolution_mm']:.3g} mm ({why}; "
                f"{cells[0] if cells else 0} of half that at edges of light and in parts thinner than "
                f"{s.get('volume_thin_below_mm', 0):.3g} mm, {100 * s.get('volume_thin_fraction', 0):.1f}% of the "
                f"surface), {s['volume_unknowns']} unknowns; "
                f"near field within {max(s['cutoff_mm']):.3g} mm ({s['near_field_pairs']} evaluations); entering "
                f"{s['entering_power']:.4g} W, exitant {ex[0]:.4g}/{ex[1]:.4g}/{ex[2]:.4g} W (r/g/b); {t}")
    far = (f" (area lights: geodesic near zone within {max(s['near_mm']):.3g} mm, {s['far_field']} far field "
           f"beyond)" if "near_mm" in s else "")
    if s.get("geodesic_pairs_computed", s.get("pairs_found")) != s.get("pairs_found"):
        far += f", {s['geodesic_pairs_computed']} geodesic distances computed"
    zones = ", ".join(f"{k[5:]} {v}" for k, v in s.items() if k.startswith("zone_"))
    far += f" [zones: {zones}]" if zones and result.model == "auto" else ""
    return (f"{result.model}: {s['entry_samples']} entry samples, {s.get('pairs_found', 0)} pairs within "
            f"{max(s['cutoff_mm']):.3g} mm{far}; entering {s['entering_power']:.4g} W, exitant "
            f"{ex[0]:.4g}/{ex[1]:.4g}/{ex[2]:.4g} W (r/g/b); {t}")
