"""Fit the fitted curvature model (meshshade.kernels.fitted_curvature, docs/physics.md §14) to the training set and
write meshshade/kernels/data/fitted_curvature.csv (read by meshshade.kernels.fitted_curvature_table), with the
held-out errors, and the figures of fit and residuals.

The training set (tools/tables/curvature_training_set.py) holds ring-averaged Monte Carlo profiles on exact curved
shapes and on the half-space, same medium, same rings. Their ratio y = ln(R_shape / R_plane) is the curvature factor,
free of the near-field base's own error on the half-space. The model's exponent is delta + sum_j theta_j f_j
(eqs. (82)-(83)); the theta_j are fitted by weighted linear least squares to y - delta, each ring weighted by
the standard error of y (the two runs' errors in quadrature, plus a 1 % floor), with a small ridge. Rows where
either profile is below 20 standard errors are left out (noise, not shape).

The split is by shape and by medium. The shipped coefficients never see the shapes of radius HELD_OUT_RADII_TR
(in diffusion lengths: one sphere, cavity, cylinder and bore per medium) nor the media HELD_OUT_MEDIA, so the
held-out errors printed and stored are those of the shipped model. A second fit leaves out a whole family, the
bore (concave and anisotropic), and reports its errors on it: how the model carries to a shape family it has not
seen. Errors are |R_model / R_mc - 1| per ring, R_model = R_mc,plane x exp(exponent) (the curvature factor alone;
the base's half-space error is documented in §13), over rings whose ratio is known to 2 % (standard error),
split by the first-order validity measure nu (eq. (55)) at 0.25. The table holds one row per feature (its
coefficient, 9 significant digits) under the provenance header of tools/tables/_tablefile.py: this script's sha256,
the training set's path and sha256 and its own header, the split, the held-out errors (JSON), the command,
meshshade's version, commit and date.

    python tools/tables/fit_curvature_model.py [--data tools/tables/data/curvature_training.csv] [--plots docs/images]
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from meshshade.kernels.curvature import curvature_factor, curvature_ratios
from meshshade.kernels.fitted_curvature import (FEATURES, fitted_exponent, fitted_features, helix_chord_curvature,
                                                normal_curvatures)
from meshshade.kernels.optics import diffusion_params

sys.path.insert(0, str(Path(__file__).resolve().parent))  # tools/ is not a package
from _tablefile import DATA, ROOT, run_provenance, write_table  # noqa: E402

HELD_OUT_RADII_TR = (1.0,)
HELD_OUT_FAMILY = "bore"
HELD_OUT_MEDIA = ((0.95, 1.4, 0.0), (0.9, 1.5, 0.0))
#: rings whose curvature-factor standard error (both runs in quadrature, with the floor) is below this are scored
PRECISE = 0.02
MIN_SNR = 20.0
FLOOR = 0.01
RIDGE = 1e-3


def load(path):
    import csv
    with open(path) as fh:
        lines = [ln for ln in fh if not ln.startswith("#")]
    rows = list(csv.DictReader(lines))
    cols = {k: np.array([r[k] for r in rows]) for k in rows[0]}
    out = {k: (v if k == "shape" else v.astype(np.float64)) for k, v in cols.items()}
    return out


def chord_along(shape, R, r, phi, k_n):
    """The curvature along each ring's exit direction as the bake measures it, between the entry and exit points
    (docs/physics.md eq. (85)): +-1/R on the sphere and cavity (= k_n), on the cylinder and bore that of the helix
    (:func:`~meshshade.kernels.fitted_curvature.helix_chord_curvature`); ``phi`` from the first principal
    direction (around the cylinder's axis, along the bore's)."""
    out = np.array(k_n, dtype=np.float64)
    for name, sign in (("cylinder", 1.0), ("bore", -1.0)):
        m = shape == name
        around = phi[m] if name == "cylinder" else np.pi / 2 - phi[m]
        out[m] = sign * helix_chord_curvature(r[m], around, R[m])
    return out


def prepare(d):
    """Optical-unit inputs (sigma_s' = 1, so sigma_t' = 1 / alpha'), targets and weights."""
    al, eta = d["albedo_prime"], d["eta"]
    st = 1.0 / al
    r = d["s_mm"] * st
    k1, k2 = d["k1"] / st, d["k2"] / st
    phi = np.radians(d["azimuth_deg"])
    a, b, a1, b1, Am1 = (np.empty_like(r) for _ in range(5))
    for key in set(zip(al, eta)):
        m = (al == key[0]) & (eta == key[1])
        a[m], b[m] = curvature_ratios(r[m], albedo_prime=key[0], eta=key[1])
        a1[m], b1[m] = curvature_ratios(r[m], albedo_prime=key[0], eta=1.0)
        Am1[m] = float(diffusion_params(key[0], key[1]).A) - 1.0
    ka, kc, t2 = normal_curvatures(phi, k1, k2)
    delta_first = ka * a + kc * b   # the first-order kernel as the bake evaluates it: the entry point's k_n
    ka = chord_along(d["shape"], d["radius_mm"] * st, r, phi, ka)
    delta = ka * a + kc * b
    ok = (d["R_shape"] > MIN_SNR * d["R_shape_err"]) & (d["R_plane"] > MIN_SNR * d["R_plane_err"])
    y = np.log(np.where(ok, d["R_shape"], 1.0) / np.where(ok, d["R_plane"], 1.0))
    sig = np.sqrt((d["R_shape_err"] / d["R_shape"]) ** 2 + (d["R_plane_err"] / d["R_plane"]) ** 2 + FLOOR ** 2)
    nu = np.maximum(np.abs(k1), np.abs(k2)) * (np.abs(a) + np.abs(b) + 1.0)
    return dict(r=r, ka=ka, kc=kc, t2=t2, a=a, b=b, a1=a1, b1=b1, Am1=Am1, delta=delta, delta_first=delta_first,
                y=y, sig=sig, ok=ok, nu=nu, k1=k1, k2=k2, X=fitted_features(r, ka, kc, t2, a, b, a1, b1, Am1))


def split(d):
    """(train, held-out radius, held-out media) masks."""
    c = d["radius_mm"] * d["sigma_tr"]
    held_r = np.zeros(c.size, dtype=bool)
    for x in HELD_OUT_RADII_TR:
        held_r |= np.isclose(c, x, rtol=1e-6)
    held_med = np.zeros(c.size, dtype=bool)
    for al, eta, g in HELD_OUT_MEDIA:
        held_med |= np.isclose(d["albedo_prime"], al) & np.isclose(d["eta"], eta) & np.isclose(d["g"], g)
    return ~held_r & ~held_med, held_r, held_med


def fit(p, m):
    w = 1.0 / p["sig"][m]
    A = p["X"][m] * w[:, None]
    rhs = (p["y"][m] - p["delta"][m]) * w
    n = A.shape[1]
    scale = np.sqrt((A * A).sum(0)) + 1e-300
    As = A / scale
    theta = np.linalg.solve(As.T @ As + RIDGE * np.eye(n), As.T @ rhs) / scale
    return theta


def exponent(p, theta):
    return fitted_exponent(p["r"], p["ka"], p["kc"], p["t2"], p["a"], p["b"], p["a1"], p["b1"], p["Am1"], theta)


def errors(p, theta, d):
    """Per ring |model/mc - 1| for the fitted model, the first-order kernel (soft policy, the bake's) and the
    plane (no curvature)."""
    y = p["y"]
    fitted = np.exp(exponent(p, theta))
    first = curvature_factor(p["delta_first"], "soft")
    truth = np.exp(y)
    return {"fitted": np.abs(fitted / truth - 1), "first": np.abs(first / truth - 1), "plane": np.abs(1 / truth - 1)}


def summary(err, mask, nu, sig):
    out = {}
    for name, rng in (("nu<=0.25", nu <= 0.25), ("nu>0.25", nu > 0.25)):
        m = mask & rng & (sig < PRECISE)
        out[name] = {k: round(float(np.mean(v[m])), 4) for k, v in err.items()} | {"rings": int(m.sum())}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(ROOT / "tools" / "tables" / "data" / "curvature_training.csv"))
    ap.add_argument("--out", default=str(DATA / "fitted_curvature.csv"))
    ap.add_argument("--plots", default=str(ROOT / "docs" / "images"))
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    d = load(args.data)
    p = prepare(d)
    train, held_r, held_med = split(d)
    ok = p["ok"]
    theta = fit(p, train & ok)
    err = errors(p, theta, d)
    S = lambda m: summary(err, m, p["nu"], p["sig"])  # noqa: E731
    report = {"train": S(train & ok), "held-out radius": S(held_r & ok & ~held_med),
              "held-out media": S(held_med & ok & ~held_r)}
    for shape in ("sphere", "cavity", "cylinder", "bore"):
        report[f"held out, {shape}"] = S((held_r | held_med) & ok & (d["shape"] == shape))
    fam = d["shape"] == HELD_OUT_FAMILY
    err_fam = errors(p, fit(p, train & ok & ~fam), d)
    report[f"separate fit without the {HELD_OUT_FAMILY}: on the {HELD_OUT_FAMILY}"] = summary(
        err_fam, fam & ok, p["nu"], p["sig"])
    print(json.dumps({"theta": dict(zip(FEATURES, np.round(theta, 6).tolist())), **report}, indent=1))
    if args.no_write:
        return
    meta = {"provenance": run_provenance(Path(__file__), sys.argv[1:] if argv is None else argv),
            "rings": int((train & ok).sum())}
    write_data(Path(args.out), theta, report, Path(args.data), meta)
    print(f"wrote {args.out}")
    if args.plots:
        plot(d, p, theta, err, ok, Path(args.plots))


def write_data(path: Path, theta, report: dict, data: Path, meta: dict) -> None:
    """The table file: one row per feature with its coefficient, the held-out errors in the header.

    ``meta``: ``provenance`` (tools/tables/_tablefile.run_provenance), ``rings`` (the training rings) and
    optionally ``note`` (one more header entry)."""
    header = [ln.rstrip("\n")[2:] for ln in open(data) if ln.startswith("#")]
    params = {
        "training set": "\n".join([f"{Path(data).name}, whose header reads:", *header]),
        "split": f"train: every shape but those of radius {HELD_OUT_RADII_TR} / sigma_tr, every medium but "
                 f"{', '.join(str(m) for m in HELD_OUT_MEDIA)} (alpha', eta, g); {meta['rings']} rings",
        "errors": json.dumps(report),
        **({"note": meta["note"]} if meta.get("note") else {}),
    }
    write_table(
        path, ["feature", "coef"], [[f, float(f"{t:.9g}")] for f, t in zip(FEATURES, theta)], script=Path(__file__),
        provenance=meta["provenance"], params=params, inputs=[Path(data)],
        title="Coefficients of the fitted curvature model (meshshade.kernels.fitted_curvature, docs/physics.md §14)",
        description="One row per feature of fitted_curvature.FEATURES, in order: coef is its theta_j (9 significant\n"
                    "digits). errors (JSON): mean |R / R_mc - 1| per ring of the curvature factor for the fitted\n"
                    "model, the first-order kernel (soft) and the plane, on the training rings, the held-out radius\n"
                    "and media, per held-out shape, and for a separate fit without the bore on the bore; split by\n"
                    "the validity measure nu of docs/physics.md eq. (55) at 0.25.")


def plot(d, p, theta, err, ok, outdir):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(2, 4, figsize=(16, 7.5), sharex=True)
    fitted = exponent(p, theta)
    first = np.log(curvature_factor(p["delta_first"], "soft"))
    sel_media = (0.8, 0.99)
    for col, (shape, az) in enumerate((("sphere", 0), ("cavity", 0), ("cylinder", 0), ("bore", 90))):
        for row, al in enumerate(sel_media):
            ax = axes[row, col]
            for c, R in enumerate(sorted(set(d["radius_mm"][(d["shape"] == shape) & np.isclose(d["albedo_prime"], al)
                                                            & np.isclose(d["eta"], 1.3) & (d["g"] == 0)]))):
                m = (ok & (d["shape"] == shape) & np.isclose(d["albedo_prime"], al) & np.isclose(d["eta"], 1.3)
                     & (d["g"] == 0) & (d["radius_mm"] == R) & np.isclose(d["azimuth_deg"], az))
                if not m.any():
                    continue
                x = d["s_mm"][m] * d["sigma_tr"][m]
                col_c = f"C{c}"
                ax.errorbar(x, p["y"][m], yerr=p["sig"][m], fmt="o", ms=3, color=col_c,
                            label=f"R = {R * d['sigma_tr'][m][0]:.3g}/σ_tr")
                ax.plot(x, fitted[m], "-", color=col_c)
                ax.plot(x, first[m], ":", color=col_c)
            ax.set_xscale("log")
            ax.set_title(f"{shape}, φ = {az}°, α' = {al} (R σ_tr = 1 held out)", fontsize=9)
            ax.axhline(0, color="grey", lw=0.5)
            if col == 0:
                ax.set_ylabel("ln(R_shape / R_plane)")
            if row == 1:
                ax.set_xlabel("s σ_tr")
            ax.legend(fontsize=7)
    fig.suptitle("Curvature factor: Monte Carlo (dots), fitted model (solid), first-order kernel (dotted)")
    fig.tight_layout()
    fig.savefig(outdir / "fitted_curvature_fit.png", dpi=90)
    plt.close(fig)
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.5))
    train, held_r, held_med = split(d)
    for name, m, c in (("train", train & ok, "C0"), ("held-out radius", held_r & ok, "C1"),
                       ("held-out media", held_med & ok, "C2")):
        res = fitted - p["y"]
        ax[0].plot(p["nu"][m], res[m], ".", ms=2, color=c, label=name)
        ax[1].plot(p["nu"][m], (first - p["y"])[m], ".", ms=2, color=c, label=name)
    for a_, t in zip(ax, ("fitted model", "first-order kernel (soft)")):
        a_.set_xscale("log")
        a_.set_ylim(-1.5, 1.5)
        a_.axvline(0.25, color="grey", ls="--", lw=0.8)
        a_.axhline(0, color="grey", lw=0.5)
        a_.set_xlabel("validity measure ν (eq. 55)")
        a_.set_ylabel("ln(model / Monte Carlo)")
        a_.set_title(f"Residuals: {t}")
        a_.legend(fontsize=8, markerscale=4)
    fig.tight_layout()
    fig.savefig(outdir / "fitted_curvature_residuals.png", dpi=90)
    plt.close(fig)


if __name__ == "__main__":
    main()
