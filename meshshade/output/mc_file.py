"""The Monte Carlo run's files: a PLY with exitance, standard errors and tone-mapped colours, an NPZ, a JSON summary.

Builds the content from a :class:`~meshshade.montecarlo.simulation.MCResult`; :mod:`meshshade.io` writes it.
"""
from __future__ import annotations

import numpy as np

from meshshade import io
from meshshade.montecarlo import MCResult, beam_radial_power, summary_dict
from meshshade.output.tonemap import tonemap


def write_mc(result: MCResult, mesh, out, *, npz=None, summary=None) -> None:
    """Write the PLY (radiance_r/g/b W/mm^2, stderr_r/g/b, uchar colours), optional NPZ and JSON summary."""
    M, S = result.radiance, result.radiance_stderr
    props = {f"radiance_{c}": M[:, i] for i, c in enumerate("rgb")}
    props.update({f"stderr_{c}": S[:, i] for i, c in enumerate("rgb")})
    comments = ["meshshade model mc", f"meshshade material {result.material.describe()}",
                f"meshshade photons {result.photons} seed-reproducible"
                + ("" if result.photons_per_channel is None or len(set(result.photons_per_channel.tolist())) == 1
                   else " per channel " + "/".join(str(int(x)) for x in result.photons_per_channel)),
                "meshshade radiance_r/g/b: linear radiant exitance in W/mm^2; stderr_r/g/b its standard error"]
    io.write_mesh_ply(out, mesh, props, tonemap(M, operator="drago"), comments=comments)
    if npz:
        arrays = dict(radiance=M, radiance_stderr=S, face_power=result.face_power,
                      face_power_stderr=result.face_power_stderr, vertex_power=result.vertex_power,
                      vertex_areas=mesh.vertex_areas)
        if result.beam_distance is not None:
            arrays["beam_distance"] = result.beam_distance
            finite = result.beam_distance[np.isfinite(result.beam_distance)]
            edges = np.linspace(0.0, 1.000001 * float(finite.max()) if finite.size else 1.0, 101)
            power, stderr = beam_radial_power(result, mesh, edges)
            arrays.update(beam_radial_edges_mm=edges, beam_radial_power=power.T, beam_radial_power_stderr=stderr.T)
        io.write_npz(npz, **arrays)
    if summary:
        io.write_json(summary, summary_dict(result))
