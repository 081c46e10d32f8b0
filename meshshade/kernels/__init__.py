"""Pure array kernels in optical units (lengths times sigma_t', curvatures divided by sigma_t').

No I/O, no mesh objects, no logging: numbers in, float64 arrays out.
"""
