"""Materials: per-channel (RGB) reduced scattering and absorption in 1/mm, index of refraction, anisotropy.

Measured presets (:data:`PRESETS`, every one in mm^-1 for the R, G, B channels):

* 12 from Table 2 of H. W. Jensen, S. R. Marschner, M. Levoy, P. Hanrahan, "A Practical Model for Subsurface
  Light Transport", Proc. SIGGRAPH 2001, pp. 511-518 (the same values as pbrt-v3/v4's measured-media table,
  which cites that paper). All were measured with eta = 1.3 (Jensen et al. 2001, section 5). Mitsuba 0.6's copy
  of the table differs in a chicken sigma_a entry and stores the values in 1/cm-like scaled form; neither is
  repeated here.
* 30 from S. G. Narasimhan, M. Gupta, C. Donner, R. Ramamoorthi, S. K. Nayar, H. W. Jensen, "Acquiring Scattering
  Properties of Participating Media by Dilution", ACM Trans. Graph. 25(3) (Proc. SIGGRAPH 2006), pp. 1003-1012,
  Table 1, as sigma_s' = sigma_s (1 - g) and sigma_a: the values pbrt-v3/v4 ship in their measured-media table
  (pbrt-v4 src/pbrt/media.cpp). The paper measured liquids diluted in water; the index here is water's, 1.33
  (pbrt's default for these media too). Five of the table's media are left out: Coke, Pepsi, Merlot, Coors Light
  beer and grape juice have sigma_s' = 0 in at least one channel (clear liquids that scatter almost nothing:
  nothing a diffusion model can shade; :data:`NARASIMHAN_2006_LEFT_OUT`).
"""
from __future__ import annotations

import difflib
import math
import warnings
from dataclasses import dataclass

import numpy as np

from meshshade.errors import DiffusionValidityWarning, MaterialError
from meshshade.kernels.dipole import dipole_total_reflectance
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

#: name -> (sigma_s' [1/mm] RGB, sigma_a [1/mm] RGB); Narasimhan et al. 2006, Table 1 (as pbrt-v3/v4's table)
NARASIMHAN_2006_PRESETS = {
    "lowfat-milk": ((0.89187, 1.5136, 2.532), (0.002875, 0.00575, 0.0115)),
    "reduced-milk": ((2.4858, 3.1669, 4.5214), (0.0025556, 0.0051111, 0.012778)),
    "regular-milk": ((4.5513, 5.8294, 7.136), (0.0015333, 0.0046, 0.019933)),
    "espresso": ((0.72378, 0.84557, 1.0247), (4.7984, 6.5751, 8.8493)),
    "mint-mocha-coffee": ((0.31602, 0.38538, 0.48131), (3.772, 5.8228, 7.82)),
    "lowfat-soy-milk": ((0.30576, 0.34233, 0.61664), (0.0014375, 0.0071875, 0.035937)),
    "regular-soy-milk": ((0.59223, 0.73866, 1.4693), (0.0019167, 0.0095833, 0.065167)),
    "lowfat-chocolate-milk": ((0.64925, 0.83916, 1.1057), (0.0115, 0.0368, 0.1564)),
    "regular-chocolate-milk": ((1.4585, 2.1289, 2.9527), (0.010063, 0.043125, 0.14375)),
    "sprite": ((6.0306e-06, 6.4139e-06, 6.5504e-06), (0.001886, 0.0018308, 0.0020025)),
    "gatorade": ((0.0024574, 0.003007, 0.0037325), (0.024794, 0.019289, 0.008878)),
    "chardonnay": ((1.7982e-05, 1.3758e-05, 1.2023e-05), (0.010782, 0.011855, 0.023997)),
    "white-zinfandel": ((1.7501e-05, 1.9069e-05, 1.288e-05), (0.012072, 0.016184, 0.019843)),
    "budweiser-beer": ((2.4356e-05, 2.4079e-05, 1.0564e-05), (0.011492, 0.024911, 0.057786)),
    "clorox": ((0.0024035, 0.0031373, 0.003991), (0.0033542, 0.014892, 0.026297)),
    "apple-juice": ((0.00013612, 0.00015836, 0.000227), (0.012957, 0.023741, 0.052184)),
    "cranberry-juice": ((0.00010402, 0.00011646, 7.8139e-05), (0.039437, 0.094223, 0.12426)),
    "ruby-grapefruit-juice": ((0.011002, 0.010927, 0.011036), (0.085867, 0.18314, 0.25262)),
    "white-grapefruit-juice": ((0.22826, 0.23998, 0.32748), (0.0138, 0.018831, 0.056781)),
    "shampoo": ((0.0007176, 0.0008303, 0.0009016), (0.014107, 0.045693, 0.061717)),
    "strawberry-shampoo": ((0.00015671, 0.00015947, 1.518e-05), (0.01449, 0.05796, 0.075823)),
    "head-and-shoulders-shampoo": ((0.023805, 0.028804, 0.034306), (0.084621, 0.15688, 0.20365)),
    "lemon-tea-powder": ((0.040224, 0.045264, 0.051081), (2.4288, 4.5757, 7.2127)),
    "orange-powder": ((0.00015617, 0.00017482, 0.0001762), (0.001449, 0.003441, 0.007863)),
    "pink-lemonade-powder": ((0.00012103, 0.00013073, 0.00012528), (0.001165, 0.002366, 0.003195)),
    "cappuccino-powder": ((1.8436, 2.5851, 2.1662), (35.844, 49.547, 61.084)),
    "salt-powder": ((0.027333, 0.032451, 0.031979), (0.28415, 0.3257, 0.34148)),
    "sugar-powder": ((0.00022272, 0.00025513, 0.000271), (0.012638, 0.031051, 0.050124)),
    "suisse-mocha-powder": ((2.7979, 3.5452, 4.3365), (17.502, 27.004, 35.433)),
    "pacific-ocean-surface-water": ((0.0001764, 0.00032095, 0.00019617), (0.031845, 0.031324, 0.030147)),
}
#: water, the medium the dilutions were measured in
NARASIMHAN_2006_ETA = 1.33
#: media of Narasimhan et al. 2006 (in pbrt's table) that are not presets, and why
NARASIMHAN_2006_LEFT_OUT = {name: "sigma_s' = 0 in at least one channel (a clear liquid: no diffusion)"
                            for name in ("coke", "pepsi", "merlot", "coors-light-beer", "grape-juice")}

#: every preset: name -> (sigma_s' RGB, sigma_a RGB, eta, source), Jensen et al. 2001 first
PRESETS = {
    **{k: (s, a, JENSEN_2001_ETA, "Jensen et al. 2001") for k, (s, a) in JENSEN_2001_PRESETS.items()},
    **{k: (s, a, NARASIMHAN_2006_ETA, "Narasimhan et al. 2006") for k, (s, a) in NARASIMHAN_2006_PRESETS.items()},
}


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
