"""Monte Carlo reference: a random walk inside the same mesh (engine, numba kernels, interior grid, tallies)."""
