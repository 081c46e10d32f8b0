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


class DiffusionValidityWarning(UserWarning):
    """Parameters where diffusion theory is a poor approximation (very low albedo, first order out of range)."""
