"""Generate meshshade/kernels/data/incidence.csv: how the total diffuse reflectance of the half-space grows towards
grazing incidence, from exact transport (the near-field model's incidence scale, docs/physics.md §13.3, eq. (86);
read by meshshade.kernels.incidence_table).

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
standard errors (6 significant digits), one row per medium and angle, under the provenance header of
tools/tables/_tablefile.py (this script's sha256, the near-field table W_81 came from and its sha256, the command,
photons, seeds and grid, meshshade's version, commit and date). Prints one JSON line per medium.

    python tools/tables/make_incidence_table.py [--photons 200000] [--seed 4242]
        [--out meshshade/kernels/data/incidence.csv]
    python tools/tables/make_incidence_table.py --rows run.jsonl    # the table again from a run's printed lines
    python tools/tables/make_incidence_table.py --from-table meshshade/kernels/data/incidence.csv
        # an earlier table's rows kept, after the near-field table gained rows this grid does not read

About 40 min on 2 cores with the defaults.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from meshshade.kernels.near_field import near_field_total
from meshshade.materials import Material
from meshshade.montecarlo.shapes import shape_mc_profile
sys.path.insert(0, str(Path(__file__).resolve().parent))  # tools/ is not a package
from _tablefile import DATA, nodes, run_provenance, write_table  # noqa: E402

#: the near-field table behind W_81 (near_field_total): an input, hashed in the header
NEAR_FIELD = DATA / "near_field.csv"
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


def _round(a, digits: int = 6) -> np.ndarray:
    return np.vectorize(lambda x: float(f"{x:.{digits}g}"), otypes=[np.float64])(a)


def write_data(path: Path, R: np.ndarray, G: np.ndarray, E: np.ndarray, meta: dict) -> None:
    """The table file: one row per medium (x, eta, g) and incidence angle, with RHO, GAIN and GAIN_STDERR.

    ``meta``: ``provenance`` (tools/tables/_tablefile.run_provenance), ``photons``, ``seed``, ``seconds``,
    ``rebuilt`` (RHO recomputed from a run's printed lines) and optionally ``note`` (one more header entry)."""
    R, G, E = _round(R), _round(G), _round(E)
    rows = [[x, eta, g, ang, R[i, j, k, a], G[i, j, k, a], E[i, j, k, a]]
            for i, x in enumerate(X_NODES) for j, eta in enumerate(ETA_NODES) for k, g in enumerate(G_NODES)
            for a, ang in enumerate(ANGLES)]
    params = {
        "photons": f"{meta['photons']} per run (half that for x <= -2, five times for x > -1); one run at normal "
                   "incidence and one per angle",
        "seeds": f"{meta['seed']} + 1000 i + 10 j + k for the medium (X_NODES[i], ETA_NODES[j], G_NODES[k]), shared "
                 "by its angles" + ("; RHO rebuilt from the run's printed lines (--rows)" if meta["rebuilt"] else ""),
        "monte carlo seconds": f"{meta['seconds']:.0f}",
        "x_nodes": nodes(X_NODES), "eta_nodes": nodes(ETA_NODES), "g_nodes": nodes(G_NODES),
        "angles_deg": nodes(ANGLES),
        **({"note": meta["note"]} if meta.get("note") else {}),
    }
    write_table(
        path, ["x", "eta", "g", "angle_deg", "rho", "gain", "gain_stderr"], rows, script=Path(__file__),
        provenance=meta["provenance"], params=params, inputs=[NEAR_FIELD],
        title="Growth of the half-space's total diffuse reflectance towards grazing incidence, from exact transport "
              "(meshshade.kernels.near_field.incidence_gain, docs/physics.md eq. (86))",
        description="One row per medium of the grid x = log10(1 - alpha') (x_nodes), eta (eta_nodes), g (g_nodes),\n"
                    "sigma_t' = 1, and incidence angle theta (angle_deg, outside, degrees): rho = (T_MC(theta) /\n"
                    "T_MC(0) - 1) / (W_81(theta) - 1), the fraction of eq. (81)'s growth W_81 that exact transport\n"
                    "shows (robust_rho: 1 where W_81 - 1 is within three standard errors, clipped to [0, 10]);\n"
                    "gain = T_MC(theta) / T_MC(0) and gain_stderr its standard error (independent-run bound);\n"
                    "6 significant digits.")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photons", type=int, default=200_000)
    ap.add_argument("--seed", type=int, default=4242)
    ap.add_argument("--out", default=str(DATA / "incidence.csv"))
    ap.add_argument("--rows", help="rebuild the table from the JSON lines a previous run printed (no Monte Carlo; "
                                   "RHO recomputed from their gains)")
    ap.add_argument("--from-table", help="keep an earlier incidence table's Monte Carlo gains and RHO verbatim "
                                         "(after the near-field table gained rows this grid does not read)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = []
    if args.from_table:
        rows, seconds, note = _rows_of_table(Path(args.from_table))
        return _finish(args, argv, rows, seconds, note)
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


def _rows_of_table(path: Path):
    """(rows, Monte Carlo seconds, note) of an earlier table of this grid, its gains, their errors and RHO kept
    verbatim: for a near-field table that changed only where this grid does not read it (rows at x > -0.3, which
    ``make_near_field_table.py --extend`` adds without touching the others; say so in the commit)."""
    from meshshade.kernels.table_files import floats, read_table

    header, cols = read_table(path.name, path.parent)
    for key, want in (("x_nodes", X_NODES), ("eta_nodes", ETA_NODES), ("g_nodes", G_NODES), ("angles_deg", ANGLES)):
        if tuple(floats(header[key])) != tuple(want):
            raise SystemExit(f"{path}: its {key} are not this grid's")
    rho, gain, err = (floats(cols[c]).reshape(-1, len(ANGLES)) for c in ("rho", "gain", "gain_stderr"))
    index = [(i, j, k) for i in range(len(X_NODES)) for j in range(len(ETA_NODES)) for k in range(len(G_NODES))]
    rows = [{"index": ix, "rho": rho[n].tolist(), "gain": gain[n].tolist(), "gain_stderr": err[n].tolist()}
            for n, ix in enumerate(index)]
    note = (f"Monte Carlo gains and RHO kept verbatim from {path.name} of {header.get('date', '?')}, commit "
            f"{header.get('commit', '?')}, command {header.get('command', '?')!r} (--from-table): the near-field "
            "table recorded under inputs differs from that run's only by its rows at x > -0.3 (alpha' < 0.5, added "
            "by make_near_field_table.py --extend), which this grid (x <= -0.3) does not read")
    return rows, float(header.get("monte carlo seconds", "0")), note


def _finish(args, argv, rows, seconds, note=None) -> int:
    given = [a for a in (sys.argv[1:] if argv is None else argv)]
    if args.rows:   # the Monte Carlo run's own options, not the file its lines were kept in
        i = given.index("--rows") if "--rows" in given else -1
        given = given[:i] + given[i + 2:] if i >= 0 else [a for a in given if not a.startswith("--rows")]
    shape = (len(X_NODES), len(ETA_NODES), len(G_NODES), len(ANGLES))
    R, G, E = np.zeros(shape), np.zeros(shape), np.zeros(shape)
    for r in rows:
        i, j, k = r["index"]
        R[i, j, k], G[i, j, k], E[i, j, k] = r["rho"], r["gain"], r["gain_stderr"]
    meta = {"provenance": run_provenance(Path(__file__), given), "photons": args.photons, "seed": args.seed,
            "seconds": seconds, "rebuilt": bool(args.rows), "note": note}
    write_data(Path(args.out), R, G, E, meta)
    print(json.dumps({"wrote": args.out, "media": len(rows), "seconds": round(meta["seconds"], 1)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
