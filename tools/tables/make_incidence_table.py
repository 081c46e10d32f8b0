"""Generate meshshade/kernels/incidence_table.py: how the total diffuse reflectance of the half-space grows towards
grazing incidence, from exact transport (the near-field model's incidence scale, docs/physics.md §13.3, eq. (86)).

The depth projection of eq. (81) (the beam's sources at depths t_k cos(theta_t)) gives each entry sample the scale
W_81(theta) = T_near(theta) / T_near(0), which overshoots the exact growth for g = 0 and falls short at eta = 1 with
strong forward scattering (validation.md "Oblique light"). For every medium of a grid in x = log10(1 - alpha'), eta
and g (sigma_t' = 1), the exact half-space Monte Carlo (meshshade.montecarlo.shapes, all scattering orders) is run
at normal incidence and at the incidence angles ANGLES (same seed for all angles of a medium, so their noise is
correlated and partly cancels in the ratio), and the table stores

    RHO = (T_MC(theta) / T_MC(0) - 1) / (W_81(theta) - 1)

(1 where W_81 - 1 is within three standard errors of the gain, clipped to [0, 10]: :func:`robust_rho`), the
fraction of eq. (81)'s growth that exact transport shows: the bake's scale is then 1 + RHO (W_81 - 1),
interpolated trilinearly in (x, eta, g) and linearly in theta_i. Also stored: the Monte Carlo's gains and their
standard errors. Prints one JSON line per medium.

    python tools/tables/make_incidence_table.py [--photons 200000] [--seed 4242]
        [--out meshshade/kernels/incidence_table.py]
    python tools/tables/make_incidence_table.py --rows run.jsonl    # the table again from a run's printed lines

About 40 min on 2 cores with the defaults.
"""
from __future__ import annotations

import argparse
import datetime
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from meshshade.kernels.near_field import near_field_total
from meshshade.materials import Material
from meshshade.montecarlo.shapes import shape_mc_profile
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "references"))  # tools/ is not a package
from _refheader import short_commit  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
#: the grid: x = log10(1 - alpha'), eta, g, and the incidence angles (degrees from the normal, outside)
X_NODES = (-3.0, -2.5, -2.0, -1.5, -1.0, -0.6, -0.3)
ETA_NODES = (1.0, 1.2, 1.4, 1.6, 2.0, 2.5)
G_NODES = (0.0, 0.4, 0.7, 0.9)
ANGLES = (40.0, 60.0, 75.0, 85.0)
#: photons per run relative to --photons, by x: high albedo (long walks, totals near 1 and so precise) gets half,
#: low albedo (short walks, small totals whose ratios are noisier) five times
def photon_factor(x: float) -> float:
    return 0.5 if x <= -2.0 else (1.0 if x <= -1.0 else 5.0)


def robust_rho(G: float, G_err: float, W: float) -> float:
    """RHO = (G - 1)/(W - 1), or 1 (eq. (81)'s own growth) where W - 1 is within three of the Monte Carlo's
    standard errors of 0 (high eta: both gains are tiny and their ratio is noise); clipped to [0, 10] (at eta = 1,
    g = 0.9 and alpha' = 0.5 exact transport grows 4.5 times as much as eq. (81) at 85 degrees)."""
    if abs(W - 1.0) <= 3.0 * G_err:
        return 1.0
    return float(min(max((G - 1.0) / (W - 1.0), 0.0), 10.0))


def gains(a: float, eta: float, g: float, photons: int, seed: int) -> dict:
    """One medium: the Monte Carlo's total at normal incidence and its gain at each angle, eq. (81)'s gain, RHO."""
    m = Material(a, 1.0 - a, eta, g)
    t0 = time.perf_counter()
    base = shape_mc_profile(m, [1.0], shape="plane", photons=photons, seed=seed)
    T0, e0 = float(base.total[0]), float(base.total_stderr[0])
    ref = near_field_total(albedo_prime=a, eta=eta, g=g)
    rho, gain, gain_err, w81 = [], [], [], []
    for ang in ANGLES:
        mc = shape_mc_profile(m, [1.0], shape="plane", photons=photons, seed=seed, incidence_deg=ang)
        T, e = float(mc.total[0]), float(mc.total_stderr[0])
        G = T / T0
        # independent-run bound on the ratio's error (the shared seed only makes it smaller)
        gain_err.append(G * math.hypot(e / T, e0 / T0))
        cos_t = math.sqrt(max(0.0, 1.0 - (math.sin(math.radians(ang)) / eta) ** 2))
        W = near_field_total(albedo_prime=a, eta=eta, g=g, cos_t=cos_t) / ref
        gain.append(G)
        w81.append(W)
        rho.append(robust_rho(G, gain_err[-1], W))
    return {"albedo_prime": a, "eta": eta, "g": g, "mc_total": T0, "gain": gain, "gain_stderr": gain_err,
            "w81": w81, "rho": rho, "mc_seconds": round(time.perf_counter() - t0, 2)}


def _nested(a: np.ndarray, indent: int = 4) -> str:
    """``a`` as a nested list literal, 6 significant digits, one line per innermost row."""
    if a.ndim == 1:
        return "[" + ", ".join(f"{x:.6g}" for x in a) + "]"
    pad = " " * indent
    inner = f",\n{pad}".join(_nested(x, indent + 1) for x in a)
    return f"[\n{pad}{inner}]"


def write_module(path: Path, rows: list, meta: dict) -> None:
    shape = (len(X_NODES), len(ETA_NODES), len(G_NODES), len(ANGLES))
    R, G, E = np.zeros(shape), np.zeros(shape), np.zeros(shape)
    for r in rows:
        i, j, k = r["index"]
        R[i, j, k], G[i, j, k], E[i, j, k] = r["rho"], r["gain"], r["gain_stderr"]
    lines = [
        '"""How the half-space\'s total diffuse reflectance grows towards grazing incidence, from exact transport',
        "(meshshade.kernels.near_field.incidence_gain, docs/physics.md eq. (86)), generated by",
        f"``python tools/tables/make_incidence_table.py{(' ' + meta['argv']) if meta['argv'] else ''}`` -- "
        "do not edit.",
        "",
        f"Provenance: meshshade {meta['version']} at commit {meta['commit']}, {meta['date']}; exact half-space Monte",
        f"Carlo with {meta['photons']} photons per run (half that for log10(1 - alpha') <= -2, five times for > -1),",
        f"one seed per medium from {meta['seed']}, shared by its angles; {meta['seconds']:.0f} s of Monte Carlo in all"
        + (";\nRHO rebuilt from the run's printed lines (--rows)." if meta.get("rebuilt") else "."),
        "RHO[i, j, k, a] = (T_MC(theta_a) / T_MC(0) - 1) / (W_81(theta_a) - 1) for X_NODES[i] = log10(1 - alpha'),",
        "ETA_NODES[j], G_NODES[k] and the incidence angles ANGLES[a] (degrees, outside); GAIN = T_MC(theta) / T_MC(0)",
        'and GAIN_STDERR its standard error (independent-run bound)."""',
        "import numpy as np",
        "",
        f"X_NODES = np.array({list(X_NODES)!r})",
        f"ETA_NODES = np.array({list(ETA_NODES)!r})",
        f"G_NODES = np.array({list(G_NODES)!r})",
        f"ANGLES = np.array({list(ANGLES)!r})",
        f"RHO = np.array({_nested(R)})",
        f"GAIN = np.array({_nested(G)})",
        f"GAIN_STDERR = np.array({_nested(E)})",
        "",
    ]
    path.write_text("\n".join(lines))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photons", type=int, default=200_000)
    ap.add_argument("--seed", type=int, default=4242)
    ap.add_argument("--out", default=str(ROOT / "meshshade" / "kernels" / "incidence_table.py"))
    ap.add_argument("--rows", help="rebuild the table from the JSON lines a previous run printed (no Monte Carlo; "
                                   "RHO recomputed from their gains)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = []
    if args.rows:
        seconds = 0.0
        for line in Path(args.rows).read_text().splitlines():
            if not line.startswith("{"):   # warnings interleaved on stderr
                continue
            r = json.loads(line)
            if "index" not in r:
                continue
            r["rho"] = [robust_rho(G, e, W) for G, e, W in zip(r["gain"], r["gain_stderr"], r["w81"])]
            seconds += r["mc_seconds"]
            rows.append(r)
        return _finish(args, argv, rows, seconds)
    for i, x in enumerate(X_NODES):
        for j, eta in enumerate(ETA_NODES):
            for k, g in enumerate(G_NODES):
                photons = int(photon_factor(x) * args.photons)
                row = gains(1.0 - 10.0 ** x, eta, g, photons, args.seed + 1000 * i + 10 * j + k)
                row["index"] = (i, j, k)
                rows.append(row)
                print(json.dumps({kk: ([round(u, 4) for u in v] if isinstance(v, list) else
                                       (round(v, 5) if isinstance(v, float) else v)) for kk, v in row.items()}),
                      flush=True)
    return _finish(args, argv, rows, time.perf_counter() - t0)


def _finish(args, argv, rows, seconds) -> int:
    commit = short_commit()
    from meshshade import __version__
    given = [a for a in (sys.argv[1:] if argv is None else argv)]
    if args.rows:   # the Monte Carlo run's own options, not the file its lines were kept in
        i = given.index("--rows") if "--rows" in given else -1
        given = given[:i] + given[i + 2:] if i >= 0 else [a for a in given if not a.startswith("--rows")]
    meta = {"argv": " ".join(given), "version": __version__, "commit": commit,
            "date": datetime.date.today().isoformat(), "photons": args.photons, "seed": args.seed,
            "seconds": seconds, "rebuilt": bool(args.rows)}
    write_module(Path(args.out), rows, meta)
    print(json.dumps({"wrote": args.out, "media": len(rows), "seconds": round(meta["seconds"], 1)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
