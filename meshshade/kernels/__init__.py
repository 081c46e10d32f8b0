"""Pure array kernels in optical units (lengths times sigma_t', curvatures divided by sigma_t').

No I/O, no mesh objects, no logging: numbers in, float64 arrays out. Modules here import only numpy, scipy,
numba, the standard library, :mod:`meshshade.errors` and each other.

Errors
------
* A material parameter outside its domain (albedo_prime not finite or outside [0, 1],
  eta not finite or outside [1, 2.5],
  or a non-number or array where a kernel takes one material) raises :class:`~meshshade.errors.MaterialError`
  in every kernel (:func:`meshshade.kernels.optics.check_material`; the cylinder also needs albedo_prime > 0).
* Any other bad argument (negative or non-finite distances, angles out of range, non-finite curvatures,
  tolerances out of range, an unknown policy name) raises ValueError. The exception is
  :mod:`~meshshade.kernels.cylinder`, whose radius, angle and tolerance errors (and series non-convergence)
  raise :class:`~meshshade.errors.MeshshadeError`: ``meshshade profile --shape cylinder`` reaches them with user
  input (a radius below half a transport length), and the CLI reports MeshshadeError as a one-line error.

MaterialError subclasses both MeshshadeError and ValueError, so callers may catch either.
"""
