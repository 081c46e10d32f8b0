"""How the bake finds each entry sample's pairs: zones of geodesic methods and far-field treatment.

A zone is (name, method within the gather radius, method beyond r_near or None, far field summed by clusters of
the dipole). ``exact`` and ``arc`` gather the whole neighbourhood with one geodesic method;
``exact_near_arc_far`` and ``exact_near_cluster_far`` use exact geodesics near the sample and arc geodesics, or
geodesics shared by clusters of samples (source_clusters.py), beyond; ``exact_near``/``arc_near`` gather only to
r_near and leave the rest to the clustered dipole (farfield.py). transport.bake assigns the zones
(:func:`assign_zones`) and runs them.
"""
from __future__ import annotations

import numpy as np

#: how a source's pairs are found: (name, method within the gather radius, method beyond r_near or None,
#: far field summed by clusters of the dipole). "exact-cluster": one exact far query per cluster of samples
#: (source_clusters.py). Zones with the far-field sum gather only to r_near.
ZONES = (("exact", "exact", None, False), ("arc", "arc", None, False),
         ("exact_near_arc_far", "exact", "arc", False), ("exact_near", "exact", None, True),
         ("arc_near", "arc", None, True), ("exact_near_cluster_far", "exact", "exact-cluster", False))
#: geodesic search radius of the near zone, in units of r_near (pairs are kept by chord <= r_near)
NEAR_MARGIN = 1.1
#: cluster size of the exact-cluster far zone, in mean edge lengths (capped at cutoff / 12)
CLUSTER_EDGES = 4.0
#: exact per-sample geodesics within this many cluster sizes (the law of cosines is used only beyond)
CLUSTER_NEAR = 3.0


def assign_zones(k: int, area, far_field: str, geodesic: str, plan, far_geodesic: str = "cluster") -> np.ndarray:
    """(k,) zone index per entry sample (see ZONES).

    Without a plan: every source uses ``geodesic``; with a far field, vertex samples gather only to r_near.
    With the auto plan: exact or arc per sample (only arc when ``geodesic`` is "arc"); vertex samples whose surroundings are flat to the cutoff
    (``plan.far_dipole``) gather to r_near and leave the rest to the clustered dipole; the other vertex samples
    keep their kernel over the whole neighbourhood, with exact geodesics in the near zone and, beyond it,
    geodesics shared by clusters of samples (``far_geodesic="cluster"``) or arc geodesics ("arc").
    """
    far = area & (far_field != "off")
    if plan is None:
        zone = np.full(k, 0 if geodesic == "exact" else 1, dtype=np.int64)
        zone[far] += 3
        return zone
    ex = plan.exact_geodesic & (geodesic == "exact")  # geodesic="arc" caps auto at arc geodesics
    if geodesic != "exact":
        far_geodesic = "arc"
    zone = np.where(ex, 0, 1).astype(np.int64)
    if far_geodesic != "none":
        zone[far & ex & ~plan.far_dipole] = 5 if far_geodesic == "cluster" else 2
    zone[far & plan.far_dipole] = np.where(ex[far & plan.far_dipole], 3, 4)
    return zone


def cluster_geometry(mesh, cut):
    """(cluster size, exact near radius) of the exact_near_cluster_far zone, mm: clusters of CLUSTER_EDGES mean
    edges (at most 1/12 of the cutoff), exact per-sample geodesics within CLUSTER_NEAR cluster sizes."""
    size = min(CLUSTER_EDGES * mesh.mean_edge_length, float(np.max(cut)) / 12.0)
    return size, CLUSTER_NEAR * size


def clusters_pay(mesh, cut) -> bool:
    """Whether sharing far-zone geodesics within clusters saves at least 30 % of the geodesic pairs (estimated
    from disc areas capped by the mesh's area: members x A(near) + centres x A(cutoff) vs members x A(cutoff))."""
    size, near_c = cluster_geometry(mesh, cut)
    per_vertex = mesh.total_area / max(mesh.n_vertices, 1)
    members = max(1.0, size * size / per_vertex)  # samples per cubic cell of a surface (order of magnitude)

    def disc(r):
        return min(np.pi * r * r, mesh.total_area)
    rc = float(np.max(cut))
    return disc(near_c) / disc(rc) + disc(rc + size) / (members * disc(rc)) < 0.7


def neighbourhood_solver(method: str, mesh):
    """The geodesic neighbourhood solver of ``method`` ("exact" or "arc") for ``mesh``."""
    if method == "exact":
        from meshshade.geometry.geodesics.neighbourhoods import GeodesicNeighbourhoods  # noqa: PLC0415
        return GeodesicNeighbourhoods(mesh.vertices, mesh.faces, mesh.vertex_normals)  # skips degenerate faces
    from meshshade.geometry.geodesics.arc import FastGeodesicNeighbourhoods  # noqa: PLC0415
    return FastGeodesicNeighbourhoods(mesh.vertices, mesh.faces, mesh.vertex_normals)
