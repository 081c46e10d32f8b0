"""Comparing two models' radiance: statistics, the split image (paper's Figure 1 layout) and a heat map.

Pure functions returning dicts, arrays and matplotlib figures; nothing is written here (:mod:`meshshade.io` does that).
Relative differences are signed, ``(A - B) / B``, on luminance (Rec. 709), and only where B's luminance is
above ``floor`` times B's maximum (default 1e-3): far below the peak the ratio is noise of no visual weight.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from meshshade import io
from meshshade.errors import MaterialError, ParameterError
from meshshade.geometry.mesh import Mesh
from meshshade.light.sources import light_list
from meshshade.materials import Material
from meshshade.montecarlo import simulate
from meshshade.montecarlo.simulation import MCOptions, check_mc_options
from meshshade.names import DEFAULT_MODEL, MODELS
from meshshade.output import render
from meshshade.output.tonemap import luminance
from meshshade.raycast import make_scene
from meshshade.surface.options import KEYWORDS as SURFACE_KEYWORDS
from meshshade.surface.options import SurfaceOptions, options_from_keywords
from meshshade.surface.source_factors import SOURCE_MODELS, check_source_model
from meshshade.transport.baking import bake
from meshshade.transport.options import BakeOptions
from meshshade.volume.options import VolumeOptions

#: relative radiance floor (fraction of B's maximum luminance) below which ratios are not counted
DEFAULT_FLOOR = 1e-3
#: what ``run_comparison`` can compare: every bake model and Monte Carlo
COMPARE_MODELS = (*MODELS, "mc")


def check_floor(floor) -> float:
    """The relative floor as a float in (0, 1) (a fraction of B's maximum luminance); MeshshadeError otherwise
    (NaN would make every ratio invalid and the statistics null)."""
    try:
        x = float(floor) if not isinstance(floor, (bool, str)) else math.nan
    except (TypeError, ValueError):
        x = math.nan
    if not 0.0 < x < 1.0:
        raise ParameterError(f"floor must lie in (0, 1) (a fraction of B's maximum luminance; default "
                             f"{DEFAULT_FLOOR:g}), got {floor!r}")
    return x


def source_model_pair(source_model, models=None) -> tuple:
    """``source_model`` ("point", "beam", None, or one per model A, B) as a checked pair; MeshshadeError
    otherwise. None: each model's default (the beam for ``volume``, the point source for the others)."""
    pair = (source_model, source_model) if source_model is None or isinstance(source_model, str) \
        else tuple(source_model)
    if len(pair) != 2:
        raise ParameterError(f"source model: give one value or two (A,B) among {', '.join(SOURCE_MODELS)}, got "
                             f"{source_model!r}")
    models = tuple(models) if models is not None and len(models) == 2 else (None, None)
    return tuple(check_source_model(x if x is not None else ("beam" if m == "volume" else "point"))
                 for x, m in zip(pair, models))


def compare_labels(models, source_model=None) -> tuple:
    """The names of the two sides: the model, with ``+beam`` where a surface model's source model is the beam."""
    return tuple(m + ("+beam" if sm == "beam" and m not in ("mc", "volume") else "")
                 for m, sm in zip(models, source_model_pair(source_model, models)))


def check_models(models, source_model=None) -> tuple:
    """Exactly two model names among ``COMPARE_MODELS``, different unless their source models differ
    (``source_model``: one value or one per model); MeshshadeError otherwise."""
    if isinstance(models, str) or not all(isinstance(m, str) for m in models):
        raise ParameterError(f"models must be two model names A,B, got {models!r}")
    models = tuple(models)
    if len(models) != 2:
        raise ParameterError(f"compare needs exactly two models A,B among {', '.join(COMPARE_MODELS)}, "
                             f"got {len(models)}: {', '.join(models) or 'none'}")
    for m in models:
        if m not in COMPARE_MODELS:
            raise ParameterError(f"unknown model {m!r}; choose two among {', '.join(COMPARE_MODELS)}")
    if len(set(compare_labels(models, source_model))) < 2:
        raise ParameterError(f"compare needs two different models (or source models), got {models[0]!r} twice")
    return models


def relative_difference(a, b, *, floor: float = DEFAULT_FLOOR, mask=None):
    """Signed (A - B)/B of luminance for (..., 3) radiance arrays; NaN where B is below the floor or ~mask.
    ``floor`` in (0, 1) (:func:`check_floor`)."""
    floor = check_floor(floor)
    La, Lb = luminance(a), luminance(b)
    valid = Lb > floor * (Lb[mask].max() if mask is not None and np.any(mask) else Lb.max(initial=0.0))
    if mask is not None:
        valid &= mask
    out = np.full(La.shape, np.nan)
    out[valid] = (La[valid] - Lb[valid]) / Lb[valid]
    return out


def _summary(rel) -> dict:
    r = np.abs(rel[np.isfinite(rel)])
    if r.size == 0:
        return {"max_rel_diff": None, "mean_rel_diff": None, "p95_rel_diff": None, "count": 0}
    s = rel[np.isfinite(rel)]
    return {"max_rel_diff": float(r.max()), "mean_rel_diff": float(r.mean()),
            "p95_rel_diff": float(np.percentile(r, 95)), "mean_signed_rel_diff": float(s.mean()),
            "count": int(r.size)}


def compare_stats(vertex_a, vertex_b, *, pixel_a=None, pixel_b=None, pixel_mask=None, vertex_areas=None,
                  names=("A", "B"), floor: float = DEFAULT_FLOOR) -> dict:
    """Statistics of |A - B|/B over vertices (and pixels if given), plus each model's total exitance.

    Returns ``{"models", "floor", "vertices": {max_rel_diff, mean_rel_diff, p95_rel_diff, ...}, "pixels": {...},
    "max_rel_diff", "mean_rel_diff", "p95_rel_diff" (the vertex values), "total_exitance_W": {A: [r, g, b], ...}}``.
    Total exitance is sum M * vertex area (W, per unit light) when ``vertex_areas`` is given, else sum M.
    ``floor`` in (0, 1) (:func:`check_floor`).
    """
    floor = check_floor(floor)
    va, vb = np.asarray(vertex_a, float), np.asarray(vertex_b, float)
    w = np.ones(len(va)) if vertex_areas is None else np.asarray(vertex_areas, float)
    out = {"models": list(names), "floor": floor, "definition": "(A - B)/B of luminance where B > floor * max B"}
    out["vertices"] = _summary(relative_difference(va, vb, floor=floor))
    out.update({k: out["vertices"][k] for k in ("max_rel_diff", "mean_rel_diff", "p95_rel_diff")})
    if pixel_a is not None:
        out["pixels"] = _summary(relative_difference(pixel_a, pixel_b, floor=floor, mask=pixel_mask))
    out["total_exitance_W"] = {names[0]: (va * w[:, None]).sum(0).tolist(), names[1]: (vb * w[:, None]).sum(0).tolist()}
    return out


def split_image(a, b):
    """Left half of ``a``, right half of ``b`` (same shape (H, W, ...)), like the paper's Figure 1."""
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape:
        raise ValueError(f"images differ in shape: {a.shape} vs {b.shape}")
    out = a.copy()
    half = a.shape[1] // 2
    out[:, half:] = b[:, half:]
    return out


def heatmap_figure(rel, *, names=("A", "B"), limit=None, title=None):
    """Matplotlib figure of the signed relative difference image (NaN = background/below floor) with a colour bar."""
    import matplotlib  # lazy: heavy plotting library, needed only for figures

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: as above

    finite = np.abs(rel[np.isfinite(rel)])
    lim = limit or (float(np.percentile(finite, 99)) if finite.size else 1.0) or 1.0
    fig, ax = plt.subplots(figsize=(6.4, 5.2))
    cmap = matplotlib.colormaps["RdBu_r"].copy()
    cmap.set_bad((0.85, 0.85, 0.85, 0.0))
    im = ax.imshow(np.ma.masked_invalid(rel), cmap=cmap, vmin=-lim, vmax=lim, interpolation="nearest")
    ax.set_axis_off()
    ax.set_title(title or f"({names[0]} - {names[1]}) / {names[1]}")
    fig.colorbar(im, ax=ax, label="signed relative difference of luminance")
    return fig


@dataclass(frozen=True)
class CompareOptions:
    """What :func:`run_comparison` renders and how it compares; checked where it is made (one line naming the
    option).

    width, height, spp : the images' size and samples per pixel (:func:`~meshshade.output.render.check_image_size`)
    per_pixel : gather each pixel's exitance from the bake's entry points (:class:`~meshshade.output.render.PixelGather`)
    floor : in (0, 1), ratios only where B's luminance is above this fraction of its maximum (:func:`check_floor`)
    source_model : "point" or "beam" for both models, one per model (A, B), or None for each model's default
    """

    width: int = 256
    height: int = 256
    spp: int = 4
    per_pixel: bool = False
    floor: float = DEFAULT_FLOOR
    source_model: str | tuple | None = None

    def __post_init__(self):
        width, height, spp = render.check_image_size(self.width, self.height, self.spp)
        for name, value in (("width", width), ("height", height), ("spp", spp), ("floor", check_floor(self.floor))):
            object.__setattr__(self, name, value)
        source_model_pair(self.source_model)
        if not isinstance(self.source_model, (str, type(None))):
            object.__setattr__(self, "source_model", tuple(self.source_model))


#: run_comparison's former keyword arguments: those of CompareOptions, of the bakes' options, of the Monte Carlo's
_IMAGE_KEYWORDS = ("width", "height", "spp", "per_pixel", "floor", "source_model", "near_field")
_MC_KEYWORDS = {"mc_photons": "photons", "seed": "seed"}


def run_comparison(mesh, material, lights, models=(DEFAULT_MODEL, "dipole"), options: CompareOptions | None = None,
                   *, surface: SurfaceOptions | None = None, volume: VolumeOptions | None = None,
                   mc: MCOptions | None = None, camera=None, progress: bool | str = False, **deprecated) -> dict:
    """Bake and render ``models`` (two) with the same camera and lights; returns images, bakes and statistics.

    ``options`` (:class:`CompareOptions`): the images, the floor, the source model per side. Each side bakes
    with its model (:class:`~meshshade.transport.options.BakeOptions`) and the surface models' options ``surface``
    (:class:`~meshshade.surface.options.SurfaceOptions`, its source model the side's) or the volume's ``volume``
    (:class:`~meshshade.volume.options.VolumeOptions`). ``mc`` (Monte Carlo, seeded: :class:`~meshshade.montecarlo.simulation.MCOptions`, 1e5 photons by
    default) may be one of the models: its per-vertex exitance is rendered by interpolation. Returns ``{"camera",
    "bakes": [BakeResult, BakeResult], "images": [(rgb, alpha), (rgb, alpha)], "split": (rgb, alpha), "rel": (H, W)
    signed relative difference, "stats": dict}`` (arrays only, no files); ``labels`` in the result name the sides
    (``curved+beam``).

    Everything is checked before any work (MeshshadeError, one line): ``models`` two different names among
    ``COMPARE_MODELS``; each side's bake options (a volume side refuses the surface models' far field or
    transport); with ``mc``, the photons the run can finish; ``camera`` a Camera or None; the lights.
    ``progress`` (False, True or a task name, default "compare") is passed to each bake and Monte Carlo run.
    The former keyword arguments (``width=``, ``floor=``, ``source_model=``, ``cutoff_tol=``, ``geodesic=``,
    ``far_field=``, ``transport=``, ``mc_photons=``, ``seed=``...) are accepted with a DeprecationWarning.
    """
    options, surface, volume, mc = _comparison_options(options, surface, volume, mc, deprecated)
    models = check_models(models, options.source_model)
    sources = source_model_pair(options.source_model, models)
    labels = compare_labels(models, sources)
    if not isinstance(mesh, Mesh):
        raise ParameterError(f"run_comparison needs a meshshade Mesh (mm), got {type(mesh).__name__}")
    if not isinstance(material, Material):
        raise MaterialError(f"run_comparison needs a Material, got {type(material).__name__}")
    lights = light_list(lights)
    task = (progress if isinstance(progress, str) else "compare") if progress else False
    sides = [None if m == "mc" else BakeOptions(model=m, volume=volume, surface=replace(surface, source_model=sm),
                                                progress=task) for m, sm in zip(models, sources)]
    if "mc" in models:   # the run must finish: the estimate counts the material's channel groups
        groups = len(set(zip(material.sigma_s_prime.tolist(), material.sigma_a.tolist())))
        check_mc_options(mc.photons, seed=mc.seed, time_budget=mc.time_budget, groups=groups)
    if camera is not None and not isinstance(camera, render.Camera):
        raise ParameterError(f"camera must be a Camera or None, got {type(camera).__name__}")
    camera = camera or render.auto_camera(mesh)
    scene = make_scene(mesh.vertices, mesh.faces)
    bakes, images = [], []
    for m, side in zip(models, sides):
        if m == "mc":  # Monte Carlo reference: per-vertex exitance (per-pixel gathering does not apply)
            result = simulate(mesh, material, lights, mc, progress=task)
            res, ex = SimpleNamespace(radiance=result.radiance, timings={"mc": result.seconds}), None
        else:
            res = bake(mesh, material, lights, side)
            ex = render.PixelGather(mesh, res) if options.per_pixel else None
        images.append(render.render_radiance(mesh, res.radiance, camera, options.width, options.height, options.spp,
                                             eta=material.eta, exitance_at=ex, scene=scene))
        bakes.append(res)
    (ra, aa), (rb, _) = images
    cov = aa > 0
    # against the Monte Carlo, a bake's vertices are compared as it tallies them: averaged over their patches
    vertex = [b.patch_averaged() if "mc" in models and hasattr(b, "patch_averaged") else b.radiance for b in bakes]
    stats = compare_stats(vertex[0], vertex[1], pixel_a=ra, pixel_b=rb, pixel_mask=cov,
                          vertex_areas=mesh.vertex_areas, names=labels, floor=options.floor)
    stats["camera"] = camera.describe()
    stats["timings_s"] = {m: b.timings for m, b in zip(labels, bakes)}
    for m, b in zip(labels, bakes):  # what --model auto chose (counts per decision)
        if getattr(b, "plan", None) is not None:
            stats[f"{m}_decisions"] = b.plan.counts()
    return {"camera": camera, "labels": labels, "bakes": bakes, "images": images, "split": (split_image(ra, rb), aa),
            "rel": relative_difference(ra, rb, floor=options.floor, mask=cov), "stats": stats}


def _comparison_options(options, surface, volume, mc, deprecated: dict):
    """``(CompareOptions, SurfaceOptions, VolumeOptions, MCOptions)`` of a call of :func:`run_comparison`, its
    former keyword arguments applied with one DeprecationWarning."""
    options = CompareOptions() if options is None else options
    surface = SurfaceOptions() if surface is None else surface
    volume = VolumeOptions() if volume is None else volume
    mc = MCOptions() if mc is None else mc
    for name, value, kind in (("options", options, CompareOptions), ("surface", surface, SurfaceOptions),
                              ("volume", volume, VolumeOptions), ("mc", mc, MCOptions)):
        if not isinstance(value, kind):
            raise ParameterError(f"run_comparison: {name} must be {kind.__name__} or None, got "
                                 f"{type(value).__name__}")
    if not deprecated:
        return options, surface, volume, mc
    kw = dict(deprecated)
    warnings.warn(f"run_comparison({', '.join(f'{k}=' for k in kw)}...) is deprecated; pass options="
                  "CompareOptions(...), surface=SurfaceOptions(...), mc=MCOptions(...)", DeprecationWarning,
                  stacklevel=3)
    image = {k: kw.pop(k) for k in _IMAGE_KEYWORDS if k in kw}
    if "near_field" in image:
        near = image.pop("near_field")
        if near is not None:
            if image.get("source_model") not in (None, near):
                raise ParameterError(f"source_model={image['source_model']!r} and the deprecated near_field={near!r} "
                                     "disagree; give source_model only")
            image["source_model"] = near
    mc_kw = {_MC_KEYWORDS[k]: kw.pop(k) for k in list(kw) if k in _MC_KEYWORDS}
    kw.pop("volume_cache", None)
    with warnings.catch_warnings():   # one warning: this call's
        warnings.simplefilter("ignore", DeprecationWarning)
        unknown = sorted(set(kw) - set(SURFACE_KEYWORDS))
        if unknown:
            raise TypeError(f"run_comparison() got an unexpected keyword argument {unknown[0]!r}")
        surface = options_from_keywords(surface, {k: v for k, v in kw.items() if not (k == "far_field" and v is None)},
                                        "run_comparison")
        return replace(options, **image), surface, volume, replace(mc, **mc_kw) if mc_kw else mc


def save_comparison(cmp: dict, out_dir, *, models, metadata: dict, operator="drago", bias=0.85,
                    background=None) -> list:
    """Write split.exr/png, <model>.exr/png, heatmap.png and stats.json into ``out_dir`` (via io); returns paths."""
    out = Path(out_dir)
    written = []
    rgb, alpha = cmp["split"]
    meta = {**metadata, "model": f"left {models[0]}, right {models[1]}", "camera": cmp["camera"].describe()}
    written.append(io.write_exr(out / "split.exr", render.image_rgba(rgb, alpha), meta))
    written.append(io.write_png(out / "split.png", render.display_rgba(rgb, alpha, operator=operator, bias=bias,
                                                                      background=background)))
    for m, (r, a) in zip(models, cmp["images"]):
        written.append(io.write_exr(out / f"{m}.exr", render.image_rgba(r, a), {**meta, "model": m}))
    written.append(io.write_figure(out / "heatmap.png", heatmap_figure(cmp["rel"], names=models)))
    written.append(io.write_json(out / "stats.json", cmp["stats"]))
    return written
