"""Formatting of results: profile tables, CSV text and plots. Builds content; :mod:`meshshade.io` writes it."""
from __future__ import annotations

import io as _stdio

import numpy as np

from meshshade.errors import ParameterError

PROFILE_COLUMNS = ("model", "channel", "distance_mm", "reflectance_per_mm2")


def profile_csv_text(rows, extra_columns=()) -> str:
    """CSV with the columns ``model,channel,distance_mm,reflectance_per_mm2``, then ``stderr_per_mm2`` when a
    Monte Carlo curve is among the rows (empty for the others), then ``extra_columns`` (``radius_mm`` when
    several radii, ``azimuth_deg`` for anisotropic shapes); one line per distance."""
    rows = list(rows)
    mc = any(r.get("stderr_per_mm2") is not None for r in rows)
    cols = list(PROFILE_COLUMNS) + (["stderr_per_mm2"] if mc else []) + list(extra_columns)
    out = _stdio.StringIO()
    out.write(",".join(cols) + "\n")
    for row in rows:
        err = row.get("stderr_per_mm2")
        for k, (s, R) in enumerate(zip(row["distance_mm"], row["reflectance_per_mm2"])):
            vals = {"model": row["model"], "channel": row["channel"], "distance_mm": f"{s:.10g}",
                    "reflectance_per_mm2": f"{R:.17g}", "radius_mm": _fmt(row.get("radius_mm")),
                    "azimuth_deg": _fmt(row.get("azimuth_deg")),
                    "stderr_per_mm2": "" if err is None else f"{err[k]:.6g}"}
            out.write(",".join(vals[c] for c in cols) + "\n")
    return out.getvalue()


def _fmt(v) -> str:
    return "" if v is None else f"{v:.10g}"


def _grey(rows) -> bool:
    by = {}
    for r in rows:
        by.setdefault((r["model"], r["radius_mm"], r["azimuth_deg"]), []).append(r["reflectance_per_mm2"])
    return all(np.array_equal(v[0], w) for v in by.values() for w in v[1:])



def format_profile_table(rows, *, material, extra_columns=()) -> str:
    """A readable fixed-width table: one column per curve, one line per distance (channels merged if grey).

    ``rows`` as :func:`meshshade.profiles.profile_rows` returns them, at least one (MeshshadeError otherwise)."""
    rows = list(rows)
    if not rows:
        raise ParameterError("no profile to format: give at least one model, shape and distance")
    grey = _grey(rows)
    curves = [r for r in rows if not grey or r["channel"] == "r"]
    heads = []
    for r in curves:
        h = r["model"]
        if "radius_mm" in extra_columns or (r["radius_mm"] is not None and len({c["radius_mm"] for c in rows}) > 1):
            h += f" R={r['radius_mm']:g}"
        if "azimuth_deg" in extra_columns:
            h += f" phi={r['azimuth_deg']:g}"
        if not grey:
            h += f" [{r['channel']}]"
        heads.append(h)
    width = max([14, *(len(h) + 2 for h in heads)] + ([19] if any(c.get("stderr_per_mm2") is not None
                                                                   for c in curves) else []))
    lines = [f"# {material.describe()}", "# reflectance per unit power entering the medium [1/mm^2]",
             f"{'distance_mm':>12}" + "".join(f"{h:>{width}}" for h in heads)]
    s_all = np.unique(np.concatenate([c["distance_mm"] for c in curves]))
    for x in s_all:
        cells = []
        for c in curves:
            hit = np.flatnonzero(c["distance_mm"] == x)
            if not hit.size:
                cells.append(f"{'-':>{width}}")
            elif c.get("stderr_per_mm2") is not None:   # Monte Carlo: value and relative standard error
                v, e = c["reflectance_per_mm2"][hit[0]], c["stderr_per_mm2"][hit[0]]
                rel = f"±{100 * e / v:.1f}%" if v > 0 else ""
                cells.append(f"{f'{v:.4e}{rel}':>{width}}")
            else:
                cells.append(f"{c['reflectance_per_mm2'][hit[0]]:>{width}.6e}")
        lines.append(f"{x:>12.6g}" + "".join(cells))
    return "\n".join(lines)


def profile_figure(rows, *, material, shapes):
    """Matplotlib figure: log10 reflectance vs geodesic distance, one panel per channel (one if grey),
    one labelled curve per model, radius and azimuth."""
    import matplotlib  # lazy: heavy plotting library, needed only for figures

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: as above

    grey = _grey(rows)
    chans = ["r"] if grey else ["r", "g", "b"]
    fig, axes = plt.subplots(1, len(chans), figsize=(5.2 * len(chans), 4.2), squeeze=False)
    styles = {"dipole": "--", "exact": "-", "curved": "-.", "mc": ":"}
    radii = sorted({r["radius_mm"] for r in rows if r["radius_mm"] is not None})
    cmap = plt.get_cmap("viridis")
    labels = list(dict.fromkeys(r["model"] for r in rows))
    palette = plt.get_cmap("tab10")   # one radius: a colour per curve (point and +beam near fields apart)
    for ax, ch in zip(axes[0], chans):
        for r in (x for x in rows if x["channel"] == ch):
            R = np.where(r["reflectance_per_mm2"] > 0, r["reflectance_per_mm2"], np.nan)
            if len(radii) > 1:
                colour = cmap(radii.index(r["radius_mm"]) / max(1, len(radii) - 1) * 0.85)
            else:
                colour = palette(labels.index(r["model"]) % 10)
            label = r["model"] + (f", R0 = {r['radius_mm']:g} mm" if r["radius_mm"] is not None else "")
            if len({x["azimuth_deg"] for x in rows}) > 1:
                label += f", phi = {r['azimuth_deg']:g} deg"
            if r.get("stderr_per_mm2") is not None:   # Monte Carlo: points with 2-sigma error bars
                ax.errorbar(r["distance_mm"], R, yerr=2.0 * r["stderr_per_mm2"], fmt="o", ms=3, color=colour,
                            label=label + " (±2σ)", capsize=2, lw=1.0)
                ax.set_yscale("log")
                continue
            ax.semilogy(r["distance_mm"], R, linestyle=styles.get(r["model"].split("+")[0], "-"), color=colour,
                        label=label, lw=2.0 if r["model"].endswith("+beam") else 1.4)
        ax.set_xlabel("geodesic distance from entry point [mm]")
        ax.set_ylabel("diffuse reflectance R [1/mm$^2$]")
        ax.set_title(("" if grey else f"channel {ch}: ") + ", ".join(sorted({s.kind for s in shapes})))
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(material.describe(), fontsize=9)
    fig.tight_layout()
    return fig
