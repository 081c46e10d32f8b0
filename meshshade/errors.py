"""Exception hierarchy. The CLI catches ``MeshshadeError`` only: one line on stderr, exit code 2."""


class MeshshadeError(Exception):
    """Base class for user-facing errors (bad input, bad parameters, unwritable outputs)."""


class ParameterError(MeshshadeError, ValueError):
    """An argument outside its documented domain (a tolerance, an image size, a photon count, a model name, ...)."""


class MaterialError(MeshshadeError, ValueError):
    """Invalid optical coefficients or unknown material preset."""


class UnitsError(MeshshadeError, ValueError):
    """Unknown or invalid length unit."""


class MeshValidationError(MeshshadeError, ValueError):
    """A mesh that cannot be shaded (empty, non-finite coordinates, bad face indices, unreadable)."""


class LightError(MeshshadeError, ValueError):
    """A malformed light specification, or a light that does not reach the mesh."""


class OutputError(MeshshadeError, OSError):
    """An output that cannot be written (unwritable directory, output equal to an input)."""


class NoVolumeError(MeshshadeError):
    """The mesh encloses no volume the volume transport can resolve (a flat sheet, a winding number below 1/2
    everywhere): the bake falls back to the surface transport and says why."""


class DiffusionValidityWarning(UserWarning):
    """Parameters where diffusion theory is a poor approximation (very low albedo, first order out of range)."""
