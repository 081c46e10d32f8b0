"""Outputs of `meshshade bench`: the CSV, the Pareto plot, the markdown table and the metadata JSON.

Pure functions build text and figures from the rows of :func:`meshshade.bench.runner.run_bench`; only
:func:`write_bench` writes, through :mod:`meshshade.io` (atomic writes).
"""
from __future__ import annotations

import csv
import io as _stringio
import math
from pathlib import Path

import numpy as np

from meshshade.bench.runner import COLUMNS
from meshshade.io import write_figure, write_json, write_text

#: error levels of the "cheapest setting reaching" columns (mean relative error)
ERROR_LEVELS = (0.1, 0.01, 0.001)
FILES = {"csv": "accuracy_vs_time.csv", "plot": "pareto.png", "table": "table.md", "metadata": "metadata.json"}


def _fmt(v) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:.6g}"
    return str(v)


def csv_text(rows) -> str:
    """accuracy_vs_time.csv: one line per measurement, columns :data:`meshshade.bench.runner.COLUMNS`."""
    buf = _stringio.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(COLUMNS)
    for r in rows:
        w.writerow([_fmt(r.get(c)) for c in COLUMNS])
    return buf.getvalue()


def pareto_front(times, errors) -> np.ndarray:
    """Indices of the non-dominated points (no other point is both faster and more accurate), by time."""
    t, e = np.asarray(times, float), np.asarray(errors, float)
    ok = np.flatnonzero(np.isfinite(t) & np.isfinite(e) & (e > 0) & (t > 0))
    order = ok[np.lexsort((e[ok], t[ok]))]
    front, best = [], np.inf
    for i in order:
        if e[i] < best:
            front.append(i)
            best = e[i]
    return np.array(front, dtype=np.int64)


def _knob_label(r) -> str:
    return "default" if r["knob"] == "default" else f"{r['knob']}={r['value']}"


def _decade_limits(ax, t, e):
    """Log axes spanning at least one decade around the data (no crowded minor-tick labels)."""
    from matplotlib.ticker import LogLocator, NullFormatter  # lazy: slow import (~1 s), plots only

    for vals, setter, axis in ((t, ax.set_xlim, ax.xaxis), (e, ax.set_ylim, ax.yaxis)):
        v = np.asarray(vals, float)
        v = v[np.isfinite(v) & (v > 0)]
        if v.size:
            lo, hi = v.min() / 1.4, v.max() * 1.4
            if hi / lo < 10.0:
                mid = np.sqrt(lo * hi)
                lo, hi = mid / np.sqrt(10.0), mid * np.sqrt(10.0)
            setter(lo, hi)
        axis.set_major_locator(LogLocator(base=10.0, numticks=6))
        axis.set_minor_formatter(NullFormatter())


def pareto_figure(rows, *, title: str = ""):
    """Log-log mean relative error vs wall time, one panel per scene, one marker per model, the Pareto front
    drawn (circled). Render rows (errors over pixels, time bake + render) are open markers outside the front."""
    import matplotlib  # lazy: slow import (~1 s), plots only

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: as above

    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    models = list(dict.fromkeys(r["model"] for r in rows))
    markers = dict(zip(models, "osD^v<>ph*X"))
    colours = {m: plt.get_cmap("tab10")(i % 10) for i, m in enumerate(models)}
    ncol = min(3, max(1, len(scenes)))
    nrow = max(1, math.ceil(len(scenes) / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.6 * ncol, 3.6 * nrow), squeeze=False)
    for ax in axes.ravel()[len(scenes):]:
        ax.set_visible(False)
    for ax, sc in zip(axes.ravel(), scenes):
        sub = [r for r in rows if r["scene"] == sc]
        t = np.array([r["time_s"] for r in sub], float)
        e = np.array([r["error_mean"] for r in sub], float)
        pix = np.array([r["knob"] == "render" for r in sub], bool)
        for m in models:
            for is_pix in (False, True):
                k = [i for i, r in enumerate(sub) if r["model"] == m and e[i] > 0 and np.isfinite(e[i])
                     and pix[i] == is_pix]
                if k:
                    ax.loglog(t[k], e[k], markers[m], color=colours[m], ms=5, alpha=0.8, ls="none",
                              mfc="none" if is_pix else colours[m], label=None if is_pix else m)
        f = np.flatnonzero(~pix)[pareto_front(t[~pix], e[~pix])]  # render rows measure pixels: not in the front
        if f.size:
            ax.step(t[f], e[f], where="post", color="k", lw=0.9, alpha=0.7, label="Pareto front")
            ax.plot(t[f], e[f], "o", mfc="none", mec="k", ms=9, mew=0.8)
        stderr = [r["ref_stderr"] for r in sub if r.get("ref_stderr") is not None]
        if stderr:
            ax.axhline(float(np.median(stderr)), color="grey", ls=":", lw=1, label="MC ref. rel. stderr")
        _decade_limits(ax, t, np.concatenate([e, stderr[:1]]))
        ax.set_title(sc, fontsize=9)
        ax.set_xlabel("wall time [s]", fontsize=8)
        ax.set_ylabel("mean |relative error|", fontsize=8)
        ax.grid(True, which="both", alpha=0.25)
        ax.tick_params(labelsize=7)
    handles = {}
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(lab, h)
    fig.legend(list(handles.values()), list(handles), loc="lower center", ncol=min(8, len(handles)), fontsize=8,
               frameon=False)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout(rect=(0, 0.05, 1, 0.97))
    return fig


def _e(v) -> str:
    return "" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.2g}"


def table_markdown(rows, metadata) -> str:
    """table.md: per scene and model the default-knob errors and time, and the cheapest measured setting whose
    mean error reaches each of :data:`ERROR_LEVELS`."""
    m = metadata.get("masks", {})
    lines = [
        f"Errors are relative to the reference (channel 0, {metadata.get('material', {}).get('name', '')}); "
        f"\"max\"/\"mean\" are over vertices outside the beam's entry fan where the exact reference exceeds "
        f"{m.get('exact_floor', 1e-4):g} of its peak, or over MC patches above {m.get('mc_floor', 1e-3):g} of the "
        f"peak density with MC relative stderr <= {m.get('mc_max_rel_stderr', 0.05):g}; \"energy\" is the relative "
        "error of the total exitant power. Time: wall seconds of the bake (Monte Carlo: simulate) call, numba "
        "compilation excluded (render rows: bake + render). \"<= x\": the cheapest measured setting "
        "(any knob but render, whose errors are "
        "over pixels) with mean error <= x (time in s); \"ref\": exact, or mc (median relative stderr of the "
        "MC patches). "
        f"Load average {', '.join(f'{x:.2f}' for x in metadata.get('load_average_before', []))} before, "
        f"{', '.join(f'{x:.2f}' for x in metadata.get('load_average_after', []))} after, on "
        f"{metadata.get('machine', {}).get('cpu_count', '?')} cores.",
        "",
        "| scene | ref | model | max | mean | energy | time s | "
        + " | ".join(f"<= {x:g}" for x in ERROR_LEVELS) + " |",
        "|---|---|---|---|---|---|---|" + "---|" * len(ERROR_LEVELS),
    ]
    for sc in dict.fromkeys(r["scene"] for r in rows):
        sub = [r for r in rows if r["scene"] == sc]
        for model in dict.fromkeys(r["model"] for r in sub):
            mine = [r for r in sub if r["model"] == model]
            base = next((r for r in mine if r["knob"] == "default"), None)
            if base is None:  # mc: its smallest photon count stands in
                base = min(mine, key=lambda r: r["time_s"])
            ref = base["ref_kind"] + (f" (±{base['ref_stderr']:.1g})" if base.get("ref_stderr") else "")
            cells = []
            for lvl in ERROR_LEVELS:  # render rows measure pixels, not vertices: not comparable here
                ok = [r for r in mine if r["knob"] != "render" and np.isfinite(r["error_mean"])
                      and r["error_mean"] <= lvl]
                best = min(ok, key=lambda r: r["time_s"]) if ok else None
                cells.append(f"{_knob_label(best)} ({best['time_s']:.2g})" if best else "-")
            label = model if base["knob"] == "default" else f"{model} ({_knob_label(base)})"
            lines.append(f"| {sc} | {ref} | {label} | {_e(base['error_max'])} | {_e(base['error_mean'])} | "
                         f"{base['error_energy']:+.1e} | {base['time_s']:.3g} | " + " | ".join(cells) + " |")
            for sm in (r for r in mine if r["knob"] == "source_model"):   # the other source model: its own line
                lines.append(f"| {sc} | {ref} | {model} ({_knob_label(sm)}) | {_e(sm['error_max'])} | "
                             f"{_e(sm['error_mean'])} | {sm['error_energy']:+.1e} | {sm['time_s']:.3g} | "
                             + " | ".join("" for _ in ERROR_LEVELS) + " |")
    return "\n".join(lines) + "\n"


def write_bench(result, out_dir) -> dict:
    """Write the four outputs into ``out_dir`` (which must exist) through :mod:`meshshade.io`; returns
    {kind: path}."""
    out = Path(out_dir)
    paths = {k: out / v for k, v in FILES.items()}
    write_text(paths["csv"], csv_text(result.rows))
    write_text(paths["table"], table_markdown(result.rows, result.metadata))
    write_figure(paths["plot"], pareto_figure(result.rows, title=result.metadata.get("command", "")))
    write_json(paths["metadata"], result.metadata)
    return paths
