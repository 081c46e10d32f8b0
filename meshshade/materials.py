"""Materials: per-channel (RGB) reduced scattering and absorption in 1/mm, index of refraction, anisotropy.

The 12 measured presets are from Table 2 of H. W. Jensen, S. R. Marschner, M. Levoy, P. Hanrahan,
"A Practical Model for Subsurface Light Transport", Proc. SIGGRAPH 2001, pp. 511-518, given there in mm^-1
for the R, G, B channels (the same values as pbrt-v3/v4's measured-media table, which cites that paper).
All were measured with eta = 1.3 (Jensen et al. 2001, section 5). Mitsuba 0.6's copy of the table differs in
a chicken sigma_a entry and stores the values in 1/cm-like scaled form; neither is repeated here.
"""
from __future__ import annotations

import difflib
import math
import warnings
from dataclasses import dataclass

import numpy as np

from meshshade.errors import DiffusionValidityWarning, MaterialError
from meshshade.kernels.optics import ETA_FIT_ACCURATE, ETA_MAX, check_eta, diffusion_params

CHANNELS = ("r", "g", "b")

#: name -> (sigma_s' [1/mm] RGB, sigma_a [1/mm] RGB); Jensen et al. 2001, Table 2; eta = 1.3 for all
JENSEN_2001_PRESETS = {
    "apple": ((2.29, 2.39, 1.97), (0.0030, 0.0034, 0.046)),
    "chicken1": ((0.15, 0.21, 0.38), (0.015, 0.077, 0.19)),
    "chicken2": ((0.19, 0.25, 0.32), (0.018, 0.088, 0.20)),
    "cream": ((7.38, 5.47, 3.15), (0.0002, 0.0028, 0.0163)),
    "ketchup": ((0.18, 0.07, 0.03), (0.061, 0.97, 1.45)),
    "marble": ((2.19, 2.62, 3.00), (0.0021, 0.0041, 0.0071)),
    "potato": ((0.68, 0.70, 0.55), (0.0024, 0.0090, 0.12)),
    "skimmilk": ((0.70, 1.22, 1.90), (0.0014, 0.0025, 0.0142)),
    "skin1": ((0.74, 0.88, 1.01), (0.032, 0.17, 0.48)),
    "skin2": ((1.09, 1.59, 1.79), (0.013, 0.070, 0.145)),
    "spectralon": ((11.6, 20.4, 14.9), (0.00, 0.00, 0.00)),
    "wholemilk": ((2.55, 3.21, 3.77), (0.0011, 0.0024, 0.014)),
}
JENSEN_2001_ETA = 1.3

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
    """

    sigma_s_prime: np.ndarray
    sigma_a: np.ndarray
    eta: float = 1.3
    g: float = 0.0
    name: str = "custom"

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
        """One of the 12 measured materials of Jensen et al. 2001 (case-insensitive name)."""
        key = str(name).strip().lower().replace("-", "").replace("_", "").replace(" ", "")
        if key not in JENSEN_2001_PRESETS:
            close = difflib.get_close_matches(key, JENSEN_2001_PRESETS, n=1, cutoff=0.5)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise MaterialError(
                f"unknown material {name!r}{hint} (presets: {', '.join(sorted(JENSEN_2001_PRESETS))})"
            )
        s, a = JENSEN_2001_PRESETS[key]
        return cls(s, a, JENSEN_2001_ETA if eta is None else eta, g, key)

    @property
    def is_grey(self) -> bool:
        """True when all three channels have the same coefficients (compute once, copy three times)."""
        return bool(np.all(self.sigma_s_prime == self.sigma_s_prime[0]) and np.all(self.sigma_a == self.sigma_a[0]))

    # --- derived quantities (docs/physics.md §2.1), per channel, in mm or 1/mm --------------------------------
    @property
    def sigma_t_prime(self) -> np.ndarray:
        """Reduced extinction sigma_t' = sigma_s' + sigma_a [1/mm]."""
        return self.sigma_s_prime + self.sigma_a

    @property
    def albedo_prime(self) -> np.ndarray:
        """Reduced albedo alpha' = sigma_s'/sigma_t'."""
        return self.sigma_s_prime / self.sigma_t_prime

    @property
    def _opt(self):
        return diffusion_params(self.albedo_prime, self.eta)

    @property
    def D(self) -> np.ndarray:
        """Diffusion coefficient 1/(3 sigma_t') [mm]."""
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
        return float(self._opt.F_dr[0])

    @property
    def A(self) -> float:
        """Boundary mismatch (1 + F_dr)/(1 - F_dr)."""
        return float(self._opt.A[0])

    @property
    def z_b(self) -> np.ndarray:
        """Extrapolation distance 2 A D [mm]."""
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
