"""The surface transports' options: geodesics, cutoff, the far field, how vertex samples are summed and what enters
at each sample; frozen records, checked where they are made (a one-line :class:`~meshshade.errors.MeshshadeError`
naming the option, its value and what is allowed).

:class:`SurfaceOptions` is what :func:`meshshade.transport.bake` hands to the surface models (``dipole``, ``curved``,
``exact-sphere``, ``fitted``, ``auto``, and the volume's fallback on a mesh that encloses nothing);
:class:`AutoTolerances` are ``auto``'s decision thresholds (:func:`meshshade.surface.auto.plan_sources`).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import asdict, dataclass, field, replace

from meshshade.errors import MeshshadeError, ParameterError
from meshshade.surface.auto import CURVATURE_TOL, GEODESIC_TOL, UMBILIC_TOL, VALIDITY_TOL
from meshshade.surface.farfield import DEFAULT_FAR_TOL
from meshshade.surface.source_factors import SOURCE_MODELS

__all__ = ["SurfaceOptions", "AutoTolerances", "options_from_keywords", "FAR_FIELD_METHODS", "GEODESIC_METHODS",
           "TRANSPORTS", "RTOL_RANGE", "KEYWORDS", "renamed_value"]

FAR_FIELD_METHODS = ("off", "clustered", "pairwise")
GEODESIC_METHODS = ("exact", "arc")
TRANSPORTS = ("auto", "hierarchical", "direct")
#: the documented range of ``rtol`` (relative tolerance of the exact series) in bake and profiles
RTOL_RANGE = (1e-15, 0.1)
#: former spellings of option values (still accepted, with a DeprecationWarning): far_field="direct" (the far
#: field pair by pair, not the direct-sum transport) and far_geodesic="cluster" (sample groups, not source clusters)
RENAMED_FAR_FIELD = {"direct": "pairwise"}
RENAMED_FAR_GEODESIC = {"cluster": "shared"}


def renamed_value(name: str, value, renamed: dict, stacklevel: int = 3):
    """``value``, or its new spelling if it is a former one of option ``name`` (with a DeprecationWarning at
    ``stacklevel`` from here: 3, the caller of the function that calls this)."""
    if isinstance(value, str) and value in renamed:
        warnings.warn(f"{name}={value!r} is deprecated; use {name}={renamed[value]!r}", DeprecationWarning,
                      stacklevel=stacklevel)
        return renamed[value]
    return value


def _real(value) -> float:
    """``value`` as a float, NaN when it is not a real number (so that every range check refuses it)."""
    try:
        return float(value) if not isinstance(value, (bool, str)) else math.nan
    except (TypeError, ValueError):
        return math.nan


@dataclass(frozen=True)
class AutoTolerances:
    """``auto``'s thresholds (:func:`meshshade.surface.auto.plan_sources`, its module docstring): each a number >= 0,
    inf switching its decision off."""

    curvature_tol: float = CURVATURE_TOL
    geodesic_tol: float = GEODESIC_TOL
    umbilic_tol: float = UMBILIC_TOL
    validity_tol: float = VALIDITY_TOL

    def __post_init__(self):
        for name, v in asdict(self).items():
            if not _real(v) >= 0:   # also rejects NaN; inf switches a decision off
                raise ParameterError(f"auto tolerance {name} must be a number >= 0 (inf allowed), got {v!r}")
            object.__setattr__(self, name, float(v))

    @classmethod
    def of(cls, value) -> "AutoTolerances":
        """``value`` as AutoTolerances: itself, the defaults for None, or a dict of some of the fields."""
        if value is None:
            return cls()
        if isinstance(value, cls):
            return value
        if not isinstance(value, dict):
            raise ParameterError(f"auto_options must be AutoTolerances, a dict or None, got {type(value).__name__}")
        unknown = sorted(set(value) - set(cls.__dataclass_fields__))
        if unknown:
            raise ParameterError(f"unknown auto tolerance(s) {', '.join(map(str, unknown))}; choose among "
                                 f"{', '.join(cls.__dataclass_fields__)}")
        return cls(**value)

    def keywords(self) -> dict:
        """The thresholds as keyword arguments of :func:`~meshshade.surface.auto.plan_sources`."""
        return asdict(self)


@dataclass(frozen=True)
class SurfaceOptions:
    """How the surface models bake (their meanings in :func:`meshshade.transport.bake`'s docstring).

    source_model : "point", "beam" or None (the model's default: "point"; "beam" for the volume's fallback)
    geodesic : "exact" or "arc"
    cutoff_tol : in (0, 1), the neighbourhood: reflectance beyond it below this fraction of the dipole's total
    curvature_radius_mm : > 0 or None (2 mean edge lengths), the neighbourhood of the curvature fit [mm]
    rtol : in [1e-15, 0.1], relative tolerance of the exact sphere series
    transport : "auto", "hierarchical" or "direct": how the vertex samples are summed
    far_field : "off", "clustered", "pairwise" or None (the model's default: "clustered" for auto, "off" otherwise)
    far_tol, far_rel_tol : in (0, 1), the far field's radius (its tail's share) and relative error
    far_geodesic : "shared" or "arc", ``auto``'s far-zone geodesics
    auto : :class:`AutoTolerances` (a dict of some of them is accepted)

    ``far_field="direct"`` and ``far_geodesic="cluster"``, the former spellings of "pairwise" and "shared", are
    accepted with a DeprecationWarning.
    """

    source_model: str | None = None
    geodesic: str = "exact"
    cutoff_tol: float = 1e-4
    curvature_radius_mm: float | None = None
    rtol: float = 1e-10
    transport: str = "auto"
    far_field: str | None = None
    far_tol: float = DEFAULT_FAR_TOL
    far_rel_tol: float = 1e-2
    far_geodesic: str = "shared"
    auto: AutoTolerances = field(default_factory=AutoTolerances)

    def __post_init__(self):
        set_ = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731
        set_("far_field", renamed_value("far_field", self.far_field, RENAMED_FAR_FIELD, stacklevel=4))
        set_("far_geodesic", renamed_value("far_geodesic", self.far_geodesic, RENAMED_FAR_GEODESIC, stacklevel=4))
        sm = self.source_model
        if sm is not None and (not isinstance(sm, str) or sm.lower() not in SOURCE_MODELS):
            raise ParameterError(f"source model must be one of {', '.join(SOURCE_MODELS)}, got {sm!r}")
        set_("source_model", sm.lower() if isinstance(sm, str) else None)
        if self.geodesic not in GEODESIC_METHODS:
            raise MeshshadeError(f"unknown geodesic method {self.geodesic!r}; choose exact or arc")
        if not 0.0 < _real(self.cutoff_tol) < 1.0:
            raise MeshshadeError(f"cutoff tolerance (cutoff_tol) must lie in (0, 1), got {self.cutoff_tol!r}")
        r = self.curvature_radius_mm
        if r is not None and not 0.0 < _real(r) < math.inf:
            raise MeshshadeError(f"curvature radius must be a positive finite number of mm, got {r!r}")
        if not RTOL_RANGE[0] <= _real(self.rtol) <= RTOL_RANGE[1]:
            raise MeshshadeError(f"rtol (relative tolerance of the exact series) must lie in [{RTOL_RANGE[0]:g}, "
                                 f"{RTOL_RANGE[1]:g}], got {self.rtol!r}")
        if not (isinstance(self.transport, str) and self.transport in TRANSPORTS):
            raise MeshshadeError(f"unknown transport {self.transport!r}; choose {', '.join(TRANSPORTS)} (a built "
                                 "SurfaceTransport is passed as bake(..., reuse=...))")
        if self.far_field is not None and self.far_field not in FAR_FIELD_METHODS:
            raise MeshshadeError(f"unknown far-field method {self.far_field!r}; choose off, clustered or pairwise")
        for name in ("far_tol", "far_rel_tol"):
            if not 0.0 < _real(getattr(self, name)) < 1.0:
                raise MeshshadeError(f"{name} must lie in (0, 1), got {getattr(self, name)!r}")
        if self.far_geodesic not in ("shared", "arc"):
            raise MeshshadeError(f"unknown far_geodesic {self.far_geodesic!r}; choose shared or arc")
        set_("auto", AutoTolerances.of(self.auto))

    def far_field_of(self, model: str) -> str:
        """The far-field method for ``model``: the one given, else "clustered" for ``auto``, "off" otherwise."""
        return self.far_field or ("clustered" if model in ("auto", "volume") else "off")

    def source_model_of(self, model: str) -> str:
        """The source model for ``model``: the one given, else "beam" for ``volume`` (and its fallback), "point"."""
        return self.source_model or ("beam" if model == "volume" else "point")

    @property
    def direct_options(self) -> bool:
        """Whether options only the direct sum honours were given (a far-field method or arc far-zone geodesics):
        ``transport="auto"`` then takes the direct sum."""
        return self.far_field is not None or self.far_geodesic != "shared"


#: the former keyword arguments of the surface models' options (bake's, SurfaceTransport.build's) -> the field of
#: :class:`SurfaceOptions` each sets
KEYWORDS = {"source_model": "source_model", "near_field": "source_model", "geodesic": "geodesic",
            "cutoff_tol": "cutoff_tol", "curvature_radius_mm": "curvature_radius_mm", "rtol": "rtol",
            "transport": "transport", "far_field": "far_field", "far_tol": "far_tol", "far_rel_tol": "far_rel_tol",
            "far_geodesic": "far_geodesic", "auto_options": "auto"}


def options_from_keywords(options: SurfaceOptions | None, keywords: dict, where: str,
                          stacklevel: int = 3) -> SurfaceOptions:
    """``options`` (default ones for None) with the former keyword arguments ``keywords`` of function ``where``
    applied: each a DeprecationWarning (attributed ``stacklevel`` frames up: 3, the caller of ``where``) naming the
    record to use instead; an unknown keyword is a TypeError, as Python's own, and ``near_field`` (the former name
    of ``source_model``) that disagrees with ``source_model`` a ParameterError."""
    options = SurfaceOptions() if options is None else options
    if not isinstance(options, SurfaceOptions):
        raise ParameterError(f"{where}: options must be SurfaceOptions or None, got {type(options).__name__}")
    if not keywords:
        return options
    unknown = sorted(set(keywords) - set(KEYWORDS))
    if unknown:
        raise TypeError(f"{where}() got an unexpected keyword argument {unknown[0]!r}")
    names = ", ".join(f"{k}=" for k in keywords)
    warnings.warn(f"{where}({names}...) is deprecated; pass options=SurfaceOptions(...) "
                  "(meshshade.surface.options)", DeprecationWarning, stacklevel=stacklevel)
    if "near_field" in keywords and keywords.get("source_model") not in (None, keywords["near_field"]):
        raise ParameterError(f"source_model={keywords['source_model']!r} and the deprecated "
                             f"near_field={keywords['near_field']!r} disagree; give source_model only")
    fields_ = {KEYWORDS[k]: v for k, v in keywords.items() if not (k == "near_field" and v is None)}
    return replace(options, **fields_)
