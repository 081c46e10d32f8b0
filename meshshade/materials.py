"""Materials: per-channel (RGB) reduced scattering and absorption in 1/mm, index of refraction, anisotropy.

Measured presets: :data:`PRESETS`, their sources and values in :mod:`meshshade.material_presets` (12 from Jensen et
al. 2001, 30 from Narasimhan et al. 2006; 5 of the latter left out, :data:`NARASIMHAN_2006_LEFT_OUT`).
"""
from __future__ import annotations

import difflib
import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from meshshade.errors import DiffusionValidityWarning, MaterialError
from meshshade.kernels.dipole import dipole_total_reflectance
from meshshade.kernels.optics import ETA_FIT_ACCURATE, ETA_MAX, check_eta
from meshshade.medium import Medium, medium_of
from meshshade.material_presets import JENSEN_2001_PRESETS, NARASIMHAN_2006_LEFT_OUT, PRESETS  # noqa: F401 (re-exported)

CHANNELS = ("r", "g", "b")


def _preset_key(name) -> str:
    """Case, spaces, hyphens, underscores, '&' and 'and' do not matter: 'Head & Shoulders Shampoo' finds
    'head-and-shoulders-shampoo'."""
    text = str(name).strip().lower().replace("&", "and")
    return "".join(ch for ch in text if ch.isalnum())


_PRESET_KEYS = {_preset_key(k): k for k in PRESETS}

#: below this reduced albedo diffusion theory is a poor model (absorption comparable to scattering)
LOW_ALBEDO_WARNING = 0.5

#: largest sigma_s' and sigma_a [1/mm]: a mean free path of 1 nm, far below the wavelength of light (no transport
#: theory applies there); beyond ~1e154 /mm sigma_t'**2 overflows float64 and the kernels return inf/NaN
SIGMA_MAX = 1e6


def _rgb(name: str, value) -> np.ndarray:
    try:
        arr = np.array(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise MaterialError(f"{name} must be a number or three numbers, got {value!r}") from None
    if arr.size == 1:
        arr = np.repeat(arr, 3)
    if arr.size != 3:
        raise MaterialError(f"{name} needs 1 or 3 (RGB) values, got {arr.size}")
    return arr


@dataclass(frozen=True, eq=False)  # the generated __eq__/__hash__ fail on ndarray fields; defined below
class Material:
    """A homogeneous translucent material.

    Parameters
    ----------
    sigma_s_prime : float or (3,) float
        Reduced scattering coefficient sigma_s' = sigma_s (1 - g) [1/mm], per channel; in (0, 1e6] (``SIGMA_MAX``).
    sigma_a : float or (3,) float
        Absorption coefficient [1/mm], per channel; in [0, 1e6].
    eta : float
        Relative index of refraction of the medium (inside; outside is air, 1), in [1, 2.5]: the range of the
        Groenhuis fit of F_dr (:func:`meshshade.kernels.optics.check_eta`, docs/physics.md §2.1). Above 2.2 the
        fit's boundary mismatch A is 1-5 % off the exact Fresnel value: a ``DiffusionValidityWarning``.
    g : float
        Henyey-Greenstein anisotropy in (-1, 1); only Monte Carlo uses it (diffusion sees sigma_s' alone).
    name : str
        Label for reports.

    Attributes
    ----------
    medium : Medium
        Every per-channel constant the transports, kernels and the Monte Carlo read (:mod:`meshshade.medium`),
        computed once, here.
    """

    sigma_s_prime: np.ndarray
    sigma_a: np.ndarray
    eta: float = 1.3
    g: float = 0.0
    name: str = "custom"
    medium: Medium = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        s = _rgb("sigma_s_prime", self.sigma_s_prime)
        a = _rgb("sigma_a", self.sigma_a)
        top = f"{SIGMA_MAX:.0e}".replace("e+0", "e")
        if not np.all((s > 0) & (s <= SIGMA_MAX)):  # NaN fails both
            raise MaterialError(f"sigma_s_prime must be finite and > 0 [1/mm], at most {top}, got {s.tolist()}")
        if not np.all((a >= 0) & (a <= SIGMA_MAX)):
            raise MaterialError(f"sigma_a must be finite and >= 0 [1/mm], at most {top}, got {a.tolist()}")
        try:
            eta = float(self.eta)
            g = float(self.g)
        except (TypeError, ValueError):
            raise MaterialError(f"eta and g must be numbers, got eta={self.eta!r}, g={self.g!r}") from None
        check_eta(eta)  # the one domain of eta, shared with every kernel: [1, 2.5]
        if not math.isfinite(g) or not -1.0 < g < 1.0:
            raise MaterialError(f"g must lie in (-1, 1), got {self.g!r}")
        s.flags.writeable = False
        a.flags.writeable = False
        object.__setattr__(self, "sigma_s_prime", s)
        object.__setattr__(self, "sigma_a", a)
        object.__setattr__(self, "eta", eta)
        object.__setattr__(self, "g", g)
        object.__setattr__(self, "medium", medium_of(s, a, eta, g))
        if eta > ETA_FIT_ACCURATE:
            warnings.warn(
                f"material {self.name!r}: eta = {eta:g} is above {ETA_FIT_ACCURATE:g}, where the F_dr fit's "
                f"boundary mismatch A is 1-5 % off the exact Fresnel value (allowed up to {ETA_MAX:g}; "
                "docs/physics.md §2.1)", DiffusionValidityWarning, stacklevel=3)
        low = self.albedo_prime < LOW_ALBEDO_WARNING
        if np.any(low):
            chans = ",".join(c for c, flag in zip(CHANNELS, low) if flag)
            warnings.warn(
                f"material {self.name!r}: reduced albedo {np.round(self.albedo_prime, 4).tolist()} is below "
                f"{LOW_ALBEDO_WARNING} in channel(s) {chans}; diffusion theory is inaccurate there "
                "(results stay finite but compare with Monte Carlo)",
                DiffusionValidityWarning,
                stacklevel=3,
            )

    def _key(self) -> tuple:
        return (tuple(self.sigma_s_prime.tolist()), tuple(self.sigma_a.tolist()), self.eta, self.g, self.name)

    def __eq__(self, other):
        return self._key() == other._key() if isinstance(other, Material) else NotImplemented

    def __hash__(self):
        return hash(self._key())

    # --- constructors -------------------------------------------------------------------------------
    @classmethod
    def preset(cls, name: str, *, eta: float | None = None, g: float = 0.0) -> "Material":
        """A measured material (:data:`PRESETS`: Jensen et al. 2001, Narasimhan et al. 2006); the name is matched
        ignoring case, spaces, hyphens and underscores. ``eta`` defaults to the preset's (1.3 or 1.33)."""
        key = _preset_key(name)
        if key not in _PRESET_KEYS:
            left_out = {_preset_key(k): (k, why) for k, why in NARASIMHAN_2006_LEFT_OUT.items()}
            if key in left_out:
                raise MaterialError(f"{left_out[key][0]} (Narasimhan et al. 2006) is not a preset: "
                                    f"{left_out[key][1]}")
            close = difflib.get_close_matches(key, _PRESET_KEYS, n=1, cutoff=0.5)
            hint = f"; did you mean {_PRESET_KEYS[close[0]]!r}?" if close else ""
            raise MaterialError(f"unknown material {name!r}{hint} (meshshade materials lists the {len(PRESETS)} "
                                "presets)")
        name = _PRESET_KEYS[key]
        s, a, default_eta, _source = PRESETS[name]
        return cls(s, a, default_eta if eta is None else eta, g, name)

    @property
    def is_grey(self) -> bool:
        """True when all three channels have the same coefficients (compute once, copy three times)."""
        return bool(np.all(self.sigma_s_prime == self.sigma_s_prime[0]) and np.all(self.sigma_a == self.sigma_a[0]))

    # --- derived quantities (docs/physics.md §2.1), per channel, in mm or 1/mm --------------------------------
    @property
    def sigma_t_prime(self) -> np.ndarray:
        """Reduced extinction sigma_t' = sigma_s' + sigma_a [1/mm] (read-only, the medium's)."""
        return self.medium.sigma_t_prime

    @property
    def albedo_prime(self) -> np.ndarray:
        """Reduced albedo alpha' = sigma_s'/sigma_t' (read-only, the medium's)."""
        return self.medium.albedo_prime

    @property
    def D(self) -> np.ndarray:
        """Jensen's diffusion coefficient 1/(3 sigma_t') [mm] (d'Eon's, the volume's: ``medium.D``)."""
        return 1.0 / (3.0 * self.sigma_t_prime)

    @property
    def sigma_tr(self) -> np.ndarray:
        """Effective transport coefficient sqrt(3 sigma_a sigma_t') [1/mm]."""
        return np.sqrt(3.0 * self.sigma_a * self.sigma_t_prime)

    @property
    def z_r(self) -> np.ndarray:
        """Depth of the real source 1/sigma_t' [mm]."""
        return 1.0 / self.sigma_t_prime

    @property
    def F_dr(self) -> float:
        """Diffuse Fresnel reflectance (Groenhuis fit)."""
        return float(self.medium.jensen.F_dr[0])

    @property
    def A(self) -> float:
        """Jensen's boundary mismatch (1 + F_dr)/(1 - F_dr) (d'Eon's: ``medium.A``)."""
        return float(self.medium.jensen.A[0])

    @property
    def z_b(self) -> np.ndarray:
        """Jensen's extrapolation distance 2 A D [mm] (d'Eon's: ``medium.z_b``)."""
        return 2.0 * self.A * self.D

    @property
    def z_v(self) -> np.ndarray:
        """Height of the image source above the surface, z_r + 2 z_b [mm]."""
        return self.z_r + 2.0 * self.z_b

    @property
    def transport_length(self) -> np.ndarray:
        """Transport mean free path 1/sigma_t' [mm]."""
        return 1.0 / self.sigma_t_prime

    def channel(self, i: int) -> dict:
        """Kernel parameters of channel ``i``: ``albedo_prime``, ``eta`` and the scale ``sigma_t_prime`` [1/mm]."""
        return {"albedo_prime": float(self.albedo_prime[i]), "eta": self.eta,
                "sigma_t_prime": float(self.sigma_t_prime[i])}

    def describe(self) -> str:
        """One line with the coefficients, for logs and metadata."""
        fmt = lambda v: ",".join(f"{x:.6g}" for x in v)  # noqa: E731
        return (f"{self.name}: sigma_s'=[{fmt(self.sigma_s_prime)}] sigma_a=[{fmt(self.sigma_a)}] 1/mm, "
                f"eta={self.eta:g}, g={self.g:g}")

    def to_dict(self) -> dict:
        return {"name": self.name, "sigma_s_prime_per_mm": self.sigma_s_prime.tolist(),
                "sigma_a_per_mm": self.sigma_a.tolist(), "eta": self.eta, "g": self.g}


def material_from_options(name=None, *, sigma_s_prime=None, sigma_a=None, eta=None, g=0.0) -> Material:
    """A preset by ``name`` or a custom material from numbers (``eta`` defaults to 1.3 if not given)."""
    if name is not None:
        if sigma_s_prime is not None or sigma_a is not None:
            raise MaterialError("give either a preset name or --sigma-s-prime/--sigma-a, not both")
        return Material.preset(name, eta=eta, g=g)
    if sigma_s_prime is None or sigma_a is None:
        raise MaterialError("a material needs a preset name or both --sigma-s-prime and --sigma-a (1/mm)")
    return Material(sigma_s_prime, sigma_a, 1.3 if eta is None else eta, g)


def preset_table() -> list[dict]:
    """One row per preset (:data:`PRESETS`, in order): ``name``, ``source``, ``eta``, and per channel (r, g, b)
    ``sigma_s_prime`` and ``sigma_a`` [1/mm], the reduced albedo ``albedo_prime``, the depth of the dipole's real
    source ``z_r`` = 1/sigma_t' [mm], the diffusion length ``diffusion_length`` = 1/sigma_tr [mm] (inf without
    absorption) and ``R_d``, the planar dipole's total diffuse reflectance (the colour of a flat half-space of the
    material under white light, docs/physics.md eq. (16)).
    """
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DiffusionValidityWarning)   # low-albedo media are listed, not shaded
        for name, (_s, _a, _eta, source) in PRESETS.items():
            m = Material.preset(name)
            with np.errstate(divide="ignore"):
                length = np.where(m.sigma_tr > 0, 1.0 / np.where(m.sigma_tr > 0, m.sigma_tr, 1.0), np.inf)
            rows.append({"name": name, "source": source, "eta": m.eta,
                         "sigma_s_prime": m.sigma_s_prime.tolist(), "sigma_a": m.sigma_a.tolist(),
                         "albedo_prime": m.albedo_prime.tolist(), "z_r": m.z_r.tolist(),
                         "diffusion_length": length.tolist(),
                         "R_d": [float(dipole_total_reflectance(albedo_prime=a, eta=m.eta))
                                 for a in m.albedo_prime]})
    return rows
