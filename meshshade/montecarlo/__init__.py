"""Monte Carlo reference: a random walk inside the same mesh (engine, compiled loops, interior grid, tallies).

Modules: :mod:`~meshshade.montecarlo.simulation` (``simulate``, its options ``MCOptions``, ``MCResult``), :mod:`~meshshade.montecarlo.tallies`
(profiles, summary; the files are written by :mod:`meshshade.output.mc_file`),
:mod:`~meshshade.montecarlo.sampling` (roulette constants, HG scattering, refraction),
:mod:`~meshshade.montecarlo.emitter` (photons from the lights), :mod:`~meshshade.montecarlo.engine`
with :mod:`~meshshade.montecarlo.loops`, :mod:`~meshshade.montecarlo.fused_walk` and
:mod:`~meshshade.montecarlo.interior` (the pooled engine), :mod:`~meshshade.montecarlo.wavefront_oracle` (the
numpy baseline, a test and benchmark oracle).
"""
from meshshade.montecarlo.simulation import DEFAULT_BATCHES, TOTAL_KEYS, MCOptions, MCResult, simulate
from meshshade.montecarlo.tallies import beam_radial_power, describe_mc, mc_profile, radial_exitance, summary_dict

__all__ = ["simulate", "MCOptions", "MCResult", "TOTAL_KEYS", "DEFAULT_BATCHES", "mc_profile", "radial_exitance",
           "beam_radial_power", "summary_dict", "describe_mc"]
