"""The default bake gives the same exitance, bit for bit, on one thread and on two (every stage of the volume
transport runs on the worker threads of meshshade.pacing: the lattice's numbering, the assembly's rows, the
multigrid's chunked sums, the sources' fixed ranges and the near field per receiver do not depend on where the
blocks end)."""
from __future__ import annotations

import numba
import numpy as np
import pytest

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.transport import bake


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="numba has a single thread on this machine")
def test_one_and_two_threads_give_the_same_bake():
    V, F = icosphere(12.0, 3)
    V = V * np.array([1.0, 0.8, 1.3])                       # not convex-symmetric: shadow rays and a real lattice
    V[:, 2] += 2.0 * np.sin(V[:, 0] / 3.0)
    mesh = Mesh.from_arrays(V, F)
    light = DirectionalLight((0.3, -0.4, -0.866), 1.0)
    before = numba.get_num_threads()
    try:
        out = []
        for threads in (1, 2):
            numba.set_num_threads(threads)
            res = bake(mesh, Material.preset("skin1"), [light])
            assert res.model == "volume"
            out.append(res.radiance)
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(out[0], out[1])
