"""The plan of `meshshade bench`: which runs a mode makes, one knob varied at a time.

Every model of :data:`meshshade.transport.MODELS` is measured on every scene of the mode; knobs (the
others at ``bake``'s defaults; rows ``knob="default"`` are the baseline):

* ``rtol``: the series tolerance of ``bake`` (only models that sum a series: not ``dipole`` or ``curved``);
* ``cutoff_tol``: the neighbourhood cutoff tolerance;
* ``resolution``: mesh refinement level of the procedural scenes (icosphere level; cylinder and torus
  segments 2^(level+2));
* ``geodesic``: the other geodesic method (beams default to ``exact``; directional lights to ``arc``, because
  exact neighbourhoods of every lit vertex cost minutes even on 10k vertices);
* ``render``: per-vertex vs per-pixel rendering of a baked beam (exact references only). Time: the bake plus
  the ``render_radiance`` call (per-pixel includes building the :class:`~meshshade.output.render.PixelGather`); error:
  exitance at the pixel centres' surface points of the same orthographic camera against the exact reference;
* ``photons``: the Monte Carlo photon count (model ``mc``; against an exact reference, or against the
  reference MC run with another seed);
* ``source_model``: the other source model of ``bake`` (docs/physics.md §13; "beam" when the baseline is "point"),
  on the scenes with a Monte Carlo reference only (the exact references are diffusion's own point source).

The ``volume`` model always takes the beam source model and has no series, cutoff or geodesics: it gets the
``default``, ``resolution`` and ``render`` rows only.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from meshshade.bench.scenes import SCENES, Scene
from meshshade.errors import ParameterError
from meshshade.transport import MODELS, SurfaceOptions
from meshshade.surface.source_factors import check_source_model, source_model_keyword

KNOBS = ("default", "rtol", "cutoff_tol", "resolution", "geodesic", "render", "photons", "source_model")
#: models for which bake's rtol (series tolerance) changes nothing
NO_SERIES = ("dipole", "curved", "fitted")


def bake_defaults() -> dict:
    """``rtol``, ``cutoff_tol`` and ``geodesic`` defaults of the surface models' options
    (:class:`~meshshade.surface.options.SurfaceOptions`, kept in sync)."""
    s = SurfaceOptions()
    return {k: getattr(s, k) for k in ("rtol", "cutoff_tol", "geodesic")}


@dataclass(frozen=True)
class Run:
    """One measurement: ``scene`` with ``model`` at ``level``; ``knob``/``value`` name what differs from the
    defaults. ``settings``: bake keywords (rtol, cutoff_tol, geodesic, source_model), or ``render`` / ``photons``."""

    scene: Scene
    model: str
    knob: str
    value: str
    level: int
    settings: dict = field(default_factory=dict)


@dataclass
class BenchConfig:
    """Knob values and sizes of one bench mode; ``bench_plan`` expands it into runs."""

    scenes: tuple
    levels: dict                 # scene name -> default level (overrides the scene's)
    rtol: tuple = ()
    rtol_scenes: tuple = ()
    cutoff: tuple = ()
    cutoff_scenes: tuple = ()
    resolution: dict = field(default_factory=dict)   # scene name -> levels
    geodesic_scenes: tuple = ()
    render_scenes: tuple = ()
    render_width: int = 128
    photons: tuple = ()
    photon_scenes: tuple = ()
    mc_photons: int = 1_000_000  # photons of the MC references


QUICK = BenchConfig(
    scenes=("sphere_r5_beam", "sphere_r20_beam", "sphere_r100_beam", "sphere_r5_directional",
            "sphere_r20_directional", "sphere_r100_directional", "cylinder_r10_beam", "torus_beam",
            "torus_directional", "spot_50mm_beam", "head_200mm_beam"),
    levels={"sphere_r5_beam": 4, "sphere_r20_beam": 4, "sphere_r100_beam": 5, "sphere_r5_directional": 3,
            "sphere_r20_directional": 3, "sphere_r100_directional": 3, "cylinder_r10_beam": 3, "torus_beam": 3,
            "torus_directional": 2},
    rtol=(1e-2, 1e-4, 1e-6, 1e-13), rtol_scenes=("sphere_r20_beam",),
    cutoff=(1e-2, 1e-3, 1e-5), cutoff_scenes=("sphere_r20_directional",),
    resolution={"sphere_r20_beam": (3, 5), "sphere_r20_directional": (2,), "sphere_r100_beam": (4,)},
    geodesic_scenes=("sphere_r20_beam",),
    render_scenes=("sphere_r20_beam",), render_width=64,
    photons=(10_000, 100_000), photon_scenes=("sphere_r20_beam", "torus_beam"),
    mc_photons=1_000_000,
)

FULL = BenchConfig(
    scenes=tuple(SCENES),
    levels={},
    rtol=(1e-2, 1e-4, 1e-6, 1e-8, 1e-12, 1e-14), rtol_scenes=("sphere_r5_beam", "sphere_r20_beam",
                                                               "sphere_r100_beam", "sphere_r20_directional"),
    cutoff=(1e-2, 1e-3, 1e-5, 1e-6), cutoff_scenes=("sphere_r20_beam", "sphere_r20_directional",
                                                      "sphere_r100_directional", "torus_directional"),
    resolution={"sphere_r5_beam": (3, 4, 6), "sphere_r20_beam": (3, 4, 6), "sphere_r20_directional": (2, 3),
                "sphere_r100_directional": (3,), "cylinder_r10_beam": (3, 5), "torus_beam": (3, 5)},
    geodesic_scenes=("sphere_r5_beam", "sphere_r20_beam", "sphere_r100_beam", "cylinder_r10_beam", "torus_beam",
                     "spot_50mm_beam", "head_200mm_beam", "sphere_r5_directional", "head_200mm_directional",
                     "spot_50mm_directional"),
    render_scenes=("sphere_r5_beam", "sphere_r20_beam", "sphere_r100_beam", "cylinder_r10_beam"),
    render_width=192,
    photons=(10_000, 100_000, 1_000_000), photon_scenes=("sphere_r5_beam", "sphere_r20_beam",
                                                         "sphere_r20_directional", "torus_beam", "spot_50mm_beam"),
    mc_photons=4_000_000,
)


def bench_plan(*, quick: bool = False, scenes=None, models=None, config: BenchConfig | None = None,
               source_model: str | None = None, near_field: str | None = None) -> list:
    """The runs of a bench mode (``config`` overrides ``quick``); ``scenes`` (names of :data:`SCENES`, or
    :class:`Scene` objects) and ``models`` restrict it; ``source_model`` is the bakes' baseline source model
    (default "point"; the ``source_model`` knob measures the other one; ``near_field``: its former name,
    deprecated).

    Models default to :data:`meshshade.transport.MODELS`, so a model added there is benchmarked without a
    change here.
    """
    cfg = config or (QUICK if quick else FULL)
    source_model = check_source_model(source_model_keyword(source_model, near_field) or "point")
    other_source = "beam" if source_model == "point" else "point"
    models = tuple(MODELS) if models is None else tuple(models)
    bad = [m for m in models if m not in MODELS]
    if bad:
        raise ParameterError(f"unknown model {bad[0]!r}; choose among {', '.join(MODELS)}")
    picked = cfg.scenes if scenes is None else tuple(scenes)
    for n in picked:
        if not isinstance(n, Scene) and n not in SCENES:
            raise ParameterError(f"unknown scene {n!r}; choose among {', '.join(SCENES)}")
    if not picked:
        raise ParameterError("no scene chosen")
    d = bake_defaults()
    runs = []
    for sc in (n if isinstance(n, Scene) else SCENES[n] for n in picked):
        n = sc.name
        L = cfg.levels.get(n, sc.level)
        base = {"rtol": d["rtol"], "cutoff_tol": d["cutoff_tol"], "geodesic": sc.geodesic,
                "source_model": source_model}
        for m in models:
            if m == "volume":   # the beam source model always; rtol, cutoff and geodesics are the surface models'
                vb = {**base, "source_model": "beam"}
                runs.append(Run(sc, m, "default", "", L, dict(vb)))
                runs += [Run(sc, m, "resolution", str(v), v, dict(vb)) for v in cfg.resolution.get(n, ()) if v != L]
                if n in cfg.render_scenes and sc.reference == "exact" and sc.light == "beam":
                    runs += [Run(sc, m, "render", mode, L, {**vb, "render": mode, "width": cfg.render_width})
                             for mode in ("per-vertex", "per-pixel")]
                continue
            runs.append(Run(sc, m, "default", "", L, dict(base)))
            if sc.reference == "mc":
                runs.append(Run(sc, m, "source_model", other_source, L, {**base, "source_model": other_source}))
            if n in cfg.rtol_scenes and m not in NO_SERIES:
                runs += [Run(sc, m, "rtol", f"{v:g}", L, {**base, "rtol": v}) for v in cfg.rtol]
            if n in cfg.cutoff_scenes:
                runs += [Run(sc, m, "cutoff_tol", f"{v:g}", L, {**base, "cutoff_tol": v}) for v in cfg.cutoff]
            runs += [Run(sc, m, "resolution", str(v), v, dict(base)) for v in cfg.resolution.get(n, ()) if v != L]
            if n in cfg.geodesic_scenes and m != "auto":  # auto chooses its geodesics per entry sample
                other = "arc" if sc.geodesic == "exact" else "exact"
                runs.append(Run(sc, m, "geodesic", other, L, {**base, "geodesic": other}))
            if n in cfg.render_scenes and sc.reference == "exact" and sc.light == "beam":
                runs += [Run(sc, m, "render", mode, L, {**base, "render": mode, "width": cfg.render_width})
                         for mode in ("per-vertex", "per-pixel")]
        if n in cfg.photon_scenes:
            runs += [Run(sc, "mc", "photons", str(p), L, {"photons": p}) for p in cfg.photons]
    return runs
