"""The bake's files: a PLY with the radiance and tone-mapped vertex colours, and optionally an NPZ of its arrays.

Builds the content from a :class:`~meshshade.transport.baking.BakeResult`; :mod:`meshshade.io` writes it.
"""
from __future__ import annotations

from meshshade import io
from meshshade.output.tonemap import tonemap
from meshshade.transport.baking import BakeResult


def write_bake(result: BakeResult, mesh, out, *, npz=None) -> None:
    """Write the PLY ``out`` (radiance_r/g/b float W/mm^2 + uchar red/green/blue, Drago tone-mapped) and, when
    ``npz`` is given, an NPZ with radiance (n, 3) W/mm^2, k1, k2 (n,) 1/mm, d1, d2 (n, 3), vertex_areas (n,) mm^2,
    cutoff_mm (3,), entry_positions (k, 3) mm, entry_power (k,) W, beam_distance (n,) mm (with a beam) and the
    auto plan's auto_kernel (k,) / auto_exact_geodesic (k,) (``model="auto"``)."""
    M = result.radiance
    props = {"radiance_r": M[:, 0], "radiance_g": M[:, 1], "radiance_b": M[:, 2]}
    colours = tonemap(M, operator="drago")
    comments = [f"meshshade model {result.model}", f"meshshade material {result.material.describe()}",
                "meshshade radiance_r/g/b: linear radiant exitance in W/mm^2 per unit light power/irradiance"]
    if result.plan is not None:
        comments.append(f"meshshade {result.plan.describe()}")
    io.write_mesh_ply(out, mesh, props, colours, comments=comments)
    if npz:
        arrays = dict(radiance=M, k1=result.k1, k2=result.k2, d1=result.d1, d2=result.d2,
                      vertex_areas=mesh.vertex_areas, cutoff_mm=result.cutoff_mm,
                      entry_positions=result.samples.positions, entry_power=result.samples.power)
        if result.beam_distance is not None:
            arrays["beam_distance"] = result.beam_distance
        if result.plan is not None:  # per entry sample: 0 dipole, 1 curved, 2 exact-sphere; exact geodesics
            arrays["auto_kernel"] = result.plan.kernel
            arrays["auto_exact_geodesic"] = result.plan.exact_geodesic
        io.write_npz(npz, **arrays)
