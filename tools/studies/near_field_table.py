"""Near the light, on the half-space: ring-averaged reflectance of each near-field model against Monte Carlo.

For the media of issue 14 (sigma_s' = 1 /mm with sigma_a 0.01 or 0.1 /mm, eta 1.0 or 1.3, g 0 or 0.8, and skin1),
a pencil beam at normal incidence, rings [max(s - h, 0), s + h] with h = max(0.1 s, 0.05 / sigma_t'): the exact
half-space Monte Carlo (meshshade.montecarlo.shapes, all scattering orders) against

* ``point``: the planar dipole, one source at z_r = 1/sigma_t' (today's model);
* ``beam-jensen``, ``beam-better``: photon beam diffusion with Jensen's or d'Eon's dipole per source, plus the
  exact single scattering (meshshade.kernels.beam_diffusion, single_scattering);
* ``beam-better-ms``: the same without single scattering;
* ``fitted``: exact single scattering plus the beam's fitted sources (meshshade.kernels.near_field, the model
  of physics.md §13 eq. (76); its table was fitted to a Monte Carlo with other seeds, on a grid the media here
  mostly fall between).

Prints one JSON line per (medium, channel, model) with the relative error per ring and of the total diffuse
reflectance, then a summary line per model (worst |error| at s >= 0.5 mm, at 0.1 <= s < 0.5 mm, and of the total).

With ``--shape sphere --radius R`` the media sit in a ball of radius R mm, the beam enters at a pole along the
inward normal, distances are geodesic, and the models are averaged over the same spherical rings:

* ``point``: the planar dipole at the chord (Jensen's usage); ``exact``: the exact sphere, one source at z_r;
* ``curved``: the first-order k1/k2 kernel, one source at z_r;
* ``beam-flat``: the half-space's fitted near field at the chord (no curvature);
* ``beam-curved``: the fitted near field times the k1/k2 kernel's curvature factor R_curved / R_d;
* ``beam-exact``: the fitted beam's sources each with the exact sphere (physics.md eq. (78)).

    python tools/studies/near_field_table.py [--photons 1000000] [--seed 1] [--csv out.csv]
    python tools/studies/near_field_table.py --shape sphere --radius 10 [--media issue|skin1]
"""
from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from meshshade.kernels.beam_diffusion import beam_diffusion_ring, beam_diffusion_total, point_source_ring
from meshshade.kernels.dipole import dipole_total_reflectance
from meshshade.kernels.curvature import curvature_profile
from meshshade.kernels.dipole import dipole_profile
from meshshade.kernels.near_field import (near_field_profile, near_field_ring, near_field_sphere_profile,
                                          near_field_total)
from meshshade.kernels.sphere import sphere_series_profile
from meshshade.kernels.single_scattering import single_scattering_ring, single_scattering_total
from meshshade.materials import Material
from meshshade.montecarlo.shapes import shape_mc_profile

DISTANCES = np.array([0.05, 0.1, 0.25, 0.5, 1.0, 2.0, 5.0])
MEDIA = [(f"sa={sa:g} eta={eta:g} g={g:g}", Material(1.0, sa, eta, g))
         for sa in (0.01, 0.1) for eta in (1.0, 1.3) for g in (0.0, 0.8)] + [("skin1", Material.preset("skin1"))]
MODELS = ("point", "beam-jensen", "beam-better", "beam-better-ms", "fitted")
SPHERE_MODELS = ("point", "exact", "curved", "beam-flat", "beam-curved", "beam-exact")
_U, _W = np.polynomial.legendre.leggauss(48)
_U, _W = 0.5 * (_U + 1.0), 0.5 * _W


def model_rings(model, lo, hi, m: Material, ch):
    """Ring averages (mm^-2) of one half-space model over rings [lo, hi] (mm), and its total diffuse reflectance."""
    st = float(m.sigma_t_prime[ch])
    a, eta, g = float(m.albedo_prime[ch]), m.eta, m.g
    lo_o, hi_o = lo * st, hi * st
    if model == "point":
        # the planar dipole is alpha' times Jensen's point source at depth 1 (closed-form ring average)
        ring = a * point_source_ring(lo_o, hi_o, 1.0, albedo_prime=a, eta=eta, variant="jensen")
        total = dipole_total_reflectance(albedo_prime=a, eta=eta)
    elif model == "fitted":
        ring, total = (near_field_ring(lo_o, hi_o, albedo_prime=a, eta=eta, g=g),
                       near_field_total(albedo_prime=a, eta=eta, g=g))
    else:
        variant = "jensen" if model == "beam-jensen" else "better"
        ring = beam_diffusion_ring(lo_o, hi_o, albedo_prime=a, eta=eta, variant=variant)
        total = beam_diffusion_total(albedo_prime=a, eta=eta, variant=variant)
        if not model.endswith("-ms"):
            ring = ring + single_scattering_ring(lo_o, hi_o, albedo_prime=a, eta=eta, g=g)
            total = total + single_scattering_total(albedo_prime=a, eta=eta, g=g)
    return ring * st * st, float(total)


def _sphere_model(model, th, R0, par, g):
    """One model's reflectance (optical units) at polar angles ``th`` on the sphere of radius R0 (optical)."""
    r, chord = th * R0, 2.0 * R0 * np.sin(0.5 * th)
    if model == "point":
        return dipole_profile(chord, **par)
    if model == "exact":
        return sphere_series_profile(th, R0_opt=R0, **par)
    if model == "curved":
        return curvature_profile(r, 0.0, k1_opt=1.0 / R0, k2_opt=1.0 / R0, **par)
    if model == "beam-flat":
        return near_field_profile(chord, g=g, **par)
    if model == "beam-curved":
        return near_field_profile(r, g=g, **par) * (curvature_profile(r, 0.0, k1_opt=1.0 / R0, k2_opt=1.0 / R0, **par)
                                                     / dipole_profile(r, **par))
    return near_field_sphere_profile(th, R0_opt=R0, g=g, **par)


_UT, _WT = np.polynomial.legendre.leggauss(600)
_UT, _WT = 0.5 * (_UT + 1.0), 0.5 * _WT


def sphere_model_rings(model, lo, hi, m: Material, ch, R_mm):
    """Ring averages over the sphere's area (weight sin(s/R)) of one model, 48-point Gauss-Legendre in s per
    ring (mm^-2), and its total over the whole sphere (600 Gauss-Legendre nodes in theta = pi u^3, graded towards
    the entry point)."""
    st = float(m.sigma_t_prime[ch])
    par, g = {"albedo_prime": float(m.albedo_prime[ch]), "eta": m.eta}, m.g
    R0 = R_mm * st
    th = (lo[:, None] + (hi - lo)[:, None] * _U[None, :]) / R_mm
    area_w = np.sin(th) * _W[None, :]
    f = _sphere_model(model, th.ravel(), R0, par, g).reshape(th.shape)
    ring = np.sum(f * area_w, axis=1) / np.sum(area_w, axis=1)
    tt = np.pi * _UT ** 3
    total = 2.0 * np.pi * R0 * R0 * float(np.sum(_sphere_model(model, tt, R0, par, g) * np.sin(tt)
                                                   * 3.0 * np.pi * _UT ** 2 * _WT))
    return ring * st * st, total


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photons", type=int, default=1_000_000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--csv", help="also write the rows as CSV")
    ap.add_argument("--shape", choices=("plane", "sphere"), default="plane")
    ap.add_argument("--radius", type=float, default=10.0, help="sphere radius [mm]")
    ap.add_argument("--media", choices=("all", "issue", "skin1"), default="all")
    args = ap.parse_args(argv)
    sphere = args.shape == "sphere"
    models = SPHERE_MODELS if sphere else MODELS
    media = [x for x in MEDIA if args.media == "all" or (x[0] == "skin1") == (args.media == "skin1")]
    worst = {m: [0.0, 0.0, 0.0] for m in models}
    rows = []
    for name, m in media:
        t0 = time.perf_counter()
        mc = shape_mc_profile(m, DISTANCES, shape=args.shape, radius_mm=args.radius if sphere else None,
                              photons=args.photons, seed=args.seed)
        secs = time.perf_counter() - t0
        channels = [0] if m.is_grey else [0, 1, 2]
        for ch in channels:
            ref, err = mc.reflectance[ch], mc.stderr[ch]
            for model in models:
                if sphere:
                    ring, total = sphere_model_rings(model, mc.lo, mc.hi, m, ch, args.radius)
                else:
                    ring, total = model_rings(model, mc.lo, mc.hi, m, ch)
                rel = ring / ref - 1.0
                rel_total = total / mc.total[ch] - 1.0 if total is not None else float("nan")
                far, near = (np.abs(rel[DISTANCES >= 0.5]).max(),
                             np.abs(rel[(DISTANCES >= 0.1) & (DISTANCES < 0.5)]).max())
                w = worst[model]
                w[0], w[1] = max(w[0], far), max(w[1], near)
                if total is not None:
                    w[2] = max(w[2], abs(rel_total))
                row = {"shape": args.shape, "radius_mm": args.radius if sphere else None, "medium": name,
                       "channel": "rgb"[ch], "model": model, "s_mm": DISTANCES.tolist(),
                       "rel_error": [round(float(x), 4) for x in rel],
                       "mc_rel_stderr": [round(float(x), 4) for x in err / ref],
                       "total_rel_error": round(rel_total, 4), "mc_total": round(float(mc.total[ch]), 5),
                       "mc_seconds": round(secs, 2)}
                rows.append(row)
                print(json.dumps(row))
    for model, (far, near, tot) in worst.items():
        print(json.dumps({"summary": model, "worst_abs_rel_error_s_ge_0.5": round(far, 4),
                          "worst_abs_rel_error_0.1_le_s_lt_0.5": round(near, 4), "worst_total": round(tot, 4)}))
    if args.csv:
        with open(args.csv, "w") as fh:
            fh.write("medium,channel,model,s_mm,rel_error,mc_rel_stderr\n")
            for r in rows:
                for s, e, se in zip(r["s_mm"], r["rel_error"], r["mc_rel_stderr"]):
                    fh.write(f"{r['medium']},{r['channel']},{r['model']},{s},{e},{se}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
