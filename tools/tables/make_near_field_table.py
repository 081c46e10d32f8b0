"""Generate meshshade/kernels/data/near_field.csv: the fitted beam sources of the near-field model
(meshshade.kernels.near_field, docs/physics.md §13; read by meshshade.kernels.near_field_table).

For every medium of a grid in x = log10(1 - alpha'), eta and g (sigma_t' = 1, so millimetres are optical units),
the exact half-space Monte Carlo (meshshade.montecarlo.shapes: pencil beam at normal incidence, all scattering
orders, rings of half-width max(0.1 s, 0.005)) gives ring-averaged reflectance and the total diffuse reflectance.
The exact single scattering (kernels.single_scattering) is subtracted, and the remainder (orders >= 2) is fitted
by non-negative least squares with point sources on the beam at fixed depths t_k, each answered by d'Eon's
dipole (kernels.beam_diffusion.point_source_ring). Each ring is weighted by its standard error, and the total
gets one more row. Writes the weights (7 significant digits) and the fit residuals, one row per medium, under the
provenance header of tools/tables/_tablefile.py (this script's sha256, the command, photons, seeds and grid,
meshshade's version, commit and date), and prints one JSON line per medium.

    python tools/tables/make_near_field_table.py [--photons 400000] [--seed 2026]
        [--out meshshade/kernels/data/near_field.csv] [--extend meshshade/kernels/data/near_field.csv]

About 20 min on 2 cores with the defaults. ``--extend FILE`` keeps FILE's rows for the nodes it has and runs only
the others (the seeds those rows would have in a whole run; its header's note says which rows came from where):
how the low-albedo nodes (x > -0.3, alpha' < 0.5; issue 47: ketchup's green and blue, alpha' 0.067 and 0.020, took
alpha' = 0.5's sources and came out 3-12 times too bright) were added.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import nnls

from meshshade.kernels.beam_diffusion import point_source_ring, point_source_total
from meshshade.kernels.single_scattering import single_scattering_ring, single_scattering_total
from meshshade.materials import Material
from meshshade.montecarlo.shapes import shape_mc_profile
sys.path.insert(0, str(Path(__file__).resolve().parent))  # tools/ is not a package
from _tablefile import DATA, nodes, run_provenance, write_table  # noqa: E402

#: the grid: x = log10(1 - alpha'), eta, g
X_NODES = (-3.0, -2.5, -2.0, -1.6, -1.4, -1.2, -1.05, -0.9, -0.75, -0.6, -0.45, -0.3,
           -0.2, -0.12, -0.07, -0.04, -0.02, -0.008)
#: below this x (high albedo) the runs are long; above it they get LOW_ALBEDO_FACTOR times the photons (cheap, and
#: their profiles fall steeply, so the far rings need them)
X_LONG_RUNS = -1.5
LOW_ALBEDO_FACTOR = 2.5
ETA_NODES = (1.0, 1.2, 1.4, 1.6, 2.0, 2.5)
G_NODES = (0.0, 0.4, 0.7, 0.9)
#: source depths on the beam [1/sigma_t']
DEPTHS = (0.01, 0.03, 0.1, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0)
#: ring centres [1/sigma_t']
RINGS = (0.01, 0.02, 0.035, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.7, 1.0, 1.4, 2.0, 2.8, 4.0, 5.6, 8.0,
         11.0, 16.0)


def fit_medium(a: float, eta: float, g: float, photons: int, seed: int) -> dict:
    s = np.array(RINGS)
    m = Material(a, 1.0 - a, eta, g)
    t0 = time.perf_counter()
    mc = shape_mc_profile(m, s, shape="plane", photons=photons, seed=seed, halfwidth_mm=np.maximum(0.1 * s, 0.005))
    secs = time.perf_counter() - t0
    ss = single_scattering_ring(mc.lo, mc.hi, albedo_prime=a, eta=eta, g=g)
    target = mc.reflectance[0] - ss
    err = mc.stderr[0]
    ok = (err > 0) & (mc.reflectance[0] > 0)
    A = np.stack([point_source_ring(mc.lo, mc.hi, t, albedo_prime=a, eta=eta) for t in DEPTHS], axis=1)
    tot_target = mc.total[0] - single_scattering_total(albedo_prime=a, eta=eta, g=g)
    tot_row = np.array([point_source_total(t, albedo_prime=a, eta=eta) for t in DEPTHS])
    tot_err = max(mc.total_stderr[0], 1e-4)
    M = np.vstack([A[ok] / err[ok, None], tot_row[None] / tot_err])
    y = np.concatenate([target[ok] / err[ok], [tot_target / tot_err]])
    w, _ = nnls(M, y, maxiter=2000)
    model = A @ w + ss
    rel = model / mc.reflectance[0] - 1.0
    good = ok & (err < 0.05 * mc.reflectance[0])
    total_model = tot_row @ w + single_scattering_total(albedo_prime=a, eta=eta, g=g)
    return {"albedo_prime": a, "eta": eta, "g": g, "weights": w.tolist(),
            "max_abs_rel_error": float(np.abs(rel[good]).max()) if np.any(good) else float("nan"),
            "total_rel_error": float(total_model / mc.total[0] - 1.0), "mc_total": float(mc.total[0]),
            "mc_seconds": round(secs, 2)}


def _round(a, digits: int = 7) -> np.ndarray:
    return np.vectorize(lambda x: float(f"{x:.{digits}g}"), otypes=[np.float64])(a)


def write_data(path: Path, W: np.ndarray, E: np.ndarray, meta: dict) -> None:
    """The table file: one row per medium (x, eta, g), its fit error and its source strengths at DEPTHS.

    ``meta``: ``provenance`` (tools/tables/_tablefile.run_provenance), ``photons``, ``seed``, ``seconds`` and
    optionally ``note`` (one more header entry)."""
    W, E = _round(W), _round(E)
    columns = ["x", "eta", "g", "fit_error", *(f"weight({d!r})" for d in DEPTHS)]
    rows = [[x, eta, g, E[i, j, k], *W[i, j, k]] for i, x in enumerate(X_NODES) for j, eta in enumerate(ETA_NODES)
            for k, g in enumerate(G_NODES)]
    params = {
        "photons": f"{meta['photons']} per medium ({LOW_ALBEDO_FACTOR:g}x that for x > {X_LONG_RUNS:g}); pencil beam "
                   "at normal incidence, all scattering orders, rings of half-width max(0.1 s, 0.005)",
        "seeds": f"{meta['seed']} + 1000 i + 10 j + k for the medium (X_NODES[i], ETA_NODES[j], G_NODES[k])",
        "monte carlo seconds": f"{meta['seconds']:.0f}",
        "x_nodes": nodes(X_NODES), "eta_nodes": nodes(ETA_NODES), "g_nodes": nodes(G_NODES),
        "depths": nodes(DEPTHS), "rings": nodes(RINGS),
        **({"note": meta["note"]} if meta.get("note") else {}),
    }
    write_table(
        path, columns, rows, script=Path(__file__), provenance=meta["provenance"], params=params,
        title="Fitted beam sources of the near-field model (meshshade.kernels.near_field, docs/physics.md §13)",
        description="One row per medium of the grid x = log10(1 - alpha') (x_nodes), eta (eta_nodes), g (g_nodes),\n"
                    "sigma_t' = 1: weight(t) is the strength of the point source at depth t on the beam (depths,\n"
                    "optical units; NNLS fit of d'Eon dipoles to the exact half-space Monte Carlo's orders >= 2 at\n"
                    "the rings and its total, 7 significant digits); fit_error the fit's largest |relative error|\n"
                    "against its Monte Carlo rings (those with stderr < 5 %).")


def _kept_rows(path: Path) -> tuple[dict, str]:
    """({(x, eta, g): row}, note) of an earlier table: its rows for this grid's nodes, and the header note saying
    which rows it gives (with its own date, commit and note)."""
    from meshshade.kernels.table_files import floats, read_table

    header, cols = read_table(path.name, path.parent)
    depths = floats(header["depths"])
    if tuple(depths) != DEPTHS:
        raise SystemExit(f"{path}: its depths {tuple(depths)} are not this grid's {DEPTHS}")
    W = np.stack([floats(cols[f"weight({float(t)!r})"]) for t in depths], axis=1)
    keys = zip(floats(cols["x"]), floats(cols["eta"]), floats(cols["g"]))
    kept = {key: {"weights": W[n].tolist(), "max_abs_rel_error": float(cols["fit_error"][n])}
            for n, key in enumerate(keys) if key[0] in X_NODES and key[1] in ETA_NODES and key[2] in G_NODES}
    xs = sorted({k[0] for k in kept})
    earlier = f" (its note: {header['note']})" if header.get("note") else ""
    note = (f"rows x in {nodes(xs)} kept from {path.name} of {header.get('date', '?')}, commit "
            f"{header.get('commit', '?')}, command {header.get('command', '?')!r}{earlier}; the other rows run now")
    return kept, note


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photons", type=int, default=400_000)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--out", default=str(DATA / "near_field.csv"))
    ap.add_argument("--extend", default=None, help="a table of this grid's eta and g nodes whose rows are kept")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = []
    kept, note = _kept_rows(Path(args.extend)) if args.extend else ({}, None)
    for i, x in enumerate(X_NODES):
        for j, eta in enumerate(ETA_NODES):
            for k, g in enumerate(G_NODES):
                if (x, eta, g) in kept:
                    rows.append({**kept[x, eta, g], "index": (i, j, k)})
                    continue
                photons = args.photons if x <= X_LONG_RUNS else int(LOW_ALBEDO_FACTOR * args.photons)
                row = fit_medium(1.0 - 10.0 ** x, eta, g, photons, args.seed + 1000 * i + 10 * j + k)
                row["index"] = (i, j, k)
                rows.append(row)
                print(json.dumps({kk: (round(v, 5) if isinstance(v, float) else v) for kk, v in row.items()
                                  if kk != "weights"}), flush=True)
    W = np.zeros((len(X_NODES), len(ETA_NODES), len(G_NODES), len(DEPTHS)))
    E = np.zeros((len(X_NODES), len(ETA_NODES), len(G_NODES)))
    for r in rows:
        W[r["index"]] = r["weights"]
        E[r["index"]] = r["max_abs_rel_error"]
    meta = {"provenance": run_provenance(Path(__file__), sys.argv[1:] if argv is None else argv),
            "photons": args.photons, "seed": args.seed, "seconds": time.perf_counter() - t0, "note": note}
    write_data(Path(args.out), W, E, meta)
    print(json.dumps({"wrote": args.out, "media": len(rows), "seconds": round(meta["seconds"], 1),
                      "worst_fit_error": max(r["max_abs_rel_error"] for r in rows),
                      "worst_total_error": max(abs(r.get("total_rel_error", 0.0)) for r in rows)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
