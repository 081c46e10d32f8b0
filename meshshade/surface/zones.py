"""How the bake finds each entry sample's pairs: zones of geodesic methods and far-field treatment.

A :class:`Zone` names the geodesic method within the gather radius, the method beyond r_near (or None) and
whether the far zone goes to the far-field sum (source clusters of the dipole). ``exact`` and ``arc`` gather the
whole neighbourhood with one geodesic method; ``exact_near_arc_far`` and ``exact_near_shared_far`` use exact
geodesics in the near zone and, beyond, arc geodesics or geodesics shared by groups of samples (sample_groups.py);
``exact_near``/``arc_near`` gather only to r_near and leave the rest to the far-field sum (farfield.py).
transport.baking assigns the zones (:func:`assign_zones`), surface.gather runs them.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from meshshade.geometry.geodesics.arc import ArcGeodesicNeighbourhoods
from meshshade.geometry.geodesics.neighbourhoods import GeodesicNeighbourhoods


class Zone(NamedTuple):
    """How the pairs of one group of entry samples are found.

    name : the zone's name (``stats["zone_<name>"]`` counts its samples)
    inner_method : geodesic method within the gather radius, "exact" or "arc"
    outer_method : method beyond r_near: None (``inner_method`` covers the whole gather radius), "arc", or
        "exact-shared" (one exact far query per group of samples, sample_groups.py)
    far_field : pairs beyond r_near go to the far-field sum (source clusters of the dipole; the zone gathers only
        to r_near)
    """

    name: str
    inner_method: str
    outer_method: str | None
    far_field: bool

    @property
    def solver_methods(self) -> tuple[str, ...]:
        """The geodesic neighbourhood solvers ("exact", "arc") the zone queries."""
        outer = () if self.outer_method is None else (self.outer_method.replace("-shared", ""),)
        return (self.inner_method,) + outer


#: the zones in the order of their index (the values :func:`assign_zones` returns)
ZONES = (Zone("exact", "exact", None, False), Zone("arc", "arc", None, False),
         Zone("exact_near_arc_far", "exact", "arc", False), Zone("exact_near", "exact", None, True),
         Zone("arc_near", "arc", None, True), Zone("exact_near_shared_far", "exact", "exact-shared", False))
EXACT, ARC, EXACT_NEAR_ARC_FAR, EXACT_NEAR, ARC_NEAR, EXACT_NEAR_SHARED_FAR = range(len(ZONES))
#: geodesic search radius of the near zone, in units of r_near (pairs are kept by chord <= r_near)
NEAR_MARGIN = 1.1
#: size of a sample group of the exact_near_shared_far zone, in mean edge lengths (capped at cutoff / 12)
GROUP_EDGES = 4.0
#: exact per-sample geodesics within this many group sizes (the law of cosines is used only beyond)
GROUP_NEAR = 3.0


def assign_zones(k: int, area, far_field: str, geodesic: str, plan, far_geodesic: str = "shared") -> np.ndarray:
    """(k,) int64 zone index (into ZONES) per entry sample.

    Without a plan: every source uses ``geodesic``; with a far field, vertex samples gather only to r_near.
    With the auto plan: exact or arc per sample (only arc when ``geodesic`` is "arc"); vertex samples whose
    surroundings are flat to the cutoff (``plan.far_dipole``) gather to r_near and leave the rest to the clustered
    dipole; the other vertex samples keep their kernel over the whole neighbourhood, with exact geodesics in the
    near zone and, beyond it, geodesics shared by groups of samples (``far_geodesic="shared"``) or arc
    geodesics ("arc"). ``area`` : (k,) bool, the vertex samples (directional and point lights).
    """
    far = area & (far_field != "off")
    if plan is None:
        zone = np.full(k, EXACT if geodesic == "exact" else ARC, dtype=np.int64)
        zone[far] = np.where(zone[far] == EXACT, EXACT_NEAR, ARC_NEAR)
        return zone
    ex = plan.exact_geodesic & (geodesic == "exact")  # geodesic="arc" caps auto at arc geodesics
    if geodesic != "exact":
        far_geodesic = "arc"
    zone = np.where(ex, EXACT, ARC).astype(np.int64)
    if far_geodesic != "none":
        split = EXACT_NEAR_SHARED_FAR if far_geodesic == "shared" else EXACT_NEAR_ARC_FAR
        zone[far & ex & ~plan.far_dipole] = split
    zone[far & plan.far_dipole] = np.where(ex[far & plan.far_dipole], EXACT_NEAR, ARC_NEAR)
    return zone


def group_geometry(mesh, cut):
    """(group size, exact near radius) of the exact_near_shared_far zone, mm: sample groups of GROUP_EDGES mean
    edges (at most 1/12 of the cutoff ``cut`` (3,) mm), exact per-sample geodesics within GROUP_NEAR group
    sizes."""
    size = min(GROUP_EDGES * mesh.mean_edge_length, float(np.max(cut)) / 12.0)
    return size, GROUP_NEAR * size


def groups_pay(mesh, cut) -> bool:
    """Whether sharing far-zone geodesics within sample groups saves at least 30 % of the geodesic pairs (estimated
    from disc areas capped by the mesh's area: members x A(near) + centres x A(cutoff) vs members x A(cutoff))."""
    size, near_c = group_geometry(mesh, cut)
    per_vertex = mesh.total_area / max(mesh.n_vertices, 1)
    members = max(1.0, size * size / per_vertex)  # samples per cubic cell of a surface (order of magnitude)

    def disc(r):
        return min(np.pi * r * r, mesh.total_area)
    rc = float(np.max(cut))
    return disc(near_c) / disc(rc) + disc(rc + size) / (members * disc(rc)) < 0.7


def neighbourhood_solver(method: str, mesh):
    """The geodesic neighbourhood solver of ``method`` ("exact" or "arc") for ``mesh``."""
    if method == "exact":
        return GeodesicNeighbourhoods(mesh.vertices, mesh.faces, mesh.vertex_normals)  # skips degenerate faces
    return ArcGeodesicNeighbourhoods(mesh.vertices, mesh.faces, mesh.vertex_normals)
