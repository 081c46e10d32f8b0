"""Odd little meshes through the curvature fit, in a child process: libigl crashed (segmentation fault, exit 139)
on some of them, which would kill pytest itself, so a crash must be a test failure instead.

libigl's ``principal_curvature`` takes each vertex's fit plane from the sum of the unit vertex normals over its
neighbourhood; where that sum vanishes it reads an uninitialised index, and where a vertex normal is 0/0 (NaN) it
recurses without end (meshshade.geometry.curvature, Robustness). The corpus holds the configurations that do that
(bow-ties, faces duplicated with opposite winding, small symmetric components, thin symmetric rods) and the other
usual suspects (fans, fins, isolated triangles, slivers, duplicated faces, coincident vertices); the random part
composes such pieces with a fixed seed.
"""
from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from meshshade.geometry import curvature, procedural
from meshshade.geometry.topology import vertex_adjacency

ROOT = Path(__file__).resolve().parents[2]
TET_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
TET_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
OCT_V = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
OCT_F = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])


def _cat(*parts):
    Vs, Fs, off = [], [], 0
    for V, F in parts:
        Vs.append(np.asarray(V, float))
        Fs.append(np.asarray(F, np.int64) + off)
        off += len(V)
    return np.vstack(Vs), np.vstack(Fs)


def _mirror_through(V, F, k):
    """(V, F) plus its point reflection through vertex k, sharing that vertex (normals cancel there)."""
    n = len(V)
    others = np.flatnonzero(np.arange(n) != k)
    index = np.full(n, k)
    index[others] = n + np.arange(n - 1)
    return np.vstack([V, 2 * V[k] - V[others]]), np.vstack([F, index[F][:, [0, 2, 1]]])


def _grid(n=6):
    x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float), indexing="ij")
    q = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).reshape(-1)
    faces = np.vstack([np.c_[q, q + n, q + 1], np.c_[q + 1, q + n, q + n + 1]])
    return np.c_[x.ravel(), y.ravel(), np.zeros(n * n)], faces


def _rod(n=12, w=0.05):
    """A closed rod of square cross-section w along x, much thinner than the fit radius."""
    sq = np.array([[w, w], [-w, w], [-w, -w], [w, -w]])
    V = np.array([[x, a, b] for x in range(n) for a, b in sq], float)
    side = [[4 * i + j, 4 * i + (j + 1) % 4, 4 * i + 4 + (j + 1) % 4, 4 * i + 4 + j]
            for i in range(n - 1) for j in range(4)]
    F = [[a, b, c] for a, b, c, d in side] + [[a, c, d] for a, b, c, d in side]
    e = 4 * (n - 1)
    return V, np.array(F + [[0, 2, 1], [0, 3, 2], [e, e + 1, e + 2], [e, e + 2, e + 3]])


def odd_meshes() -> dict:
    sphere = procedural.icosphere(10.0, 2)
    V, F = sphere
    fan = np.vstack([[0, 0, 0], [[np.cos(t), np.sin(t), 0.3 * (-1) ** i]
                                 for i, t in enumerate(np.linspace(0, 2 * np.pi, 9)[:-1])]])
    return {
        "bowtie_mirrored_tets": _mirror_through(TET_V, TET_F, 0),
        "bowtie_same_tets": (np.vstack([TET_V, -TET_V[1:]]), np.vstack([TET_F, np.array([0, 4, 5, 6])[TET_F]])),
        "bowtie_octahedra": _mirror_through(OCT_V, OCT_F, 0),
        "bowtie_spheres": _mirror_through(V, F, 0),
        "fins_at_vertex": (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0, 0, 1],
                                     [0, 0, -1]], float),
                           np.array([[0, 1, 5], [0, 2, 5], [0, 3, 5], [0, 4, 5], [0, 1, 6], [0, 3, 6]])),
        "fan_zigzag": (fan, np.array([[0, 1 + i, 1 + (i + 1) % 8] for i in range(8)])),
        "octahedron": (OCT_V, OCT_F),
        "cube": procedural.box(1.0, 1),
        "sphere_and_tiny_cube": _cat(sphere, (procedural.box(0.3, 1)[0] + 30.0, procedural.box(0.3, 1)[1])),
        "sphere_and_tiny_octahedron": _cat(sphere, (0.2 * OCT_V + 30.0, OCT_F)),
        "thin_rod": _rod(),
        "double_sided_grid": (_grid()[0], np.vstack([_grid()[1], _grid()[1][:, ::-1]])),
        "double_sided_sphere": (V, np.vstack([F, F[:, ::-1]])),
        "double_sided_patch_on_sphere": (V, np.vstack([F, F[:40, ::-1]])),
        "duplicated_faces": (V, np.vstack([F, F[:40]])),
        "isolated_triangles": _cat(*[(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]]) + 3 * i, [[0, 1, 2]])
                                     for i in range(5)]),
        "sphere_and_isolated_triangle": _cat(sphere, (np.array([[30, 0, 0], [31, 0, 0], [30, 1, 0]]), [[0, 1, 2]])),
        "slivers": _cat(sphere, (np.array([[20, 0, 0], [30, 0, 0], [25, 1e-9, 0], [25, 0, 1e-9]]),
                                 [[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])),
        "coincident_vertices": (np.vstack([V, V]), np.vstack([F, F[:, ::-1] + len(V)])),
        "single_tet": (TET_V, TET_F),
        "sphere_and_tet": _cat(sphere, (TET_V + 30.0, TET_F)),
        "flat_grid": _grid(),
    }


def random_odd_meshes(count: int, seed: int = 17) -> dict:
    """Compositions of small pieces, mirrored through shared vertices, with faces duplicated (either winding),
    deleted or welded onto coincident vertices; fixed seed."""
    rng = np.random.default_rng(seed)
    pieces = [(TET_V, TET_F), (OCT_V, OCT_F), procedural.box(1.0, 1), procedural.icosphere(1.0, 1), _grid(4),
              (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2]]))]
    out = {}
    for case in range(count):
        parts = []
        for _ in range(rng.integers(1, 4)):
            V, F = pieces[rng.integers(len(pieces))]
            scale = rng.choice([1.0, 0.1, 3.0])
            V = V * scale + (rng.integers(-1, 2, 3) * rng.choice([0.0, 0.5, 5.0]))
            if rng.random() < 0.5:
                V, F = _mirror_through(V, F, int(rng.integers(len(V))))
            parts.append((V, F))
        V, F = _cat(*parts)
        if rng.random() < 0.4:  # duplicate some faces, with either winding
            pick = F[rng.random(len(F)) < 0.5]
            F = np.vstack([F, pick[:, ::-1] if rng.random() < 0.5 else pick])
        if rng.random() < 0.3 and len(F) > 2:  # delete some faces
            F = F[rng.random(len(F)) < 0.8]
        if rng.random() < 0.3:  # weld: every vertex at a position already seen maps to its first copy
            _, first, inverse = np.unique(np.round(V, 9), axis=0, return_index=True, return_inverse=True)
            F = first[inverse.reshape(-1)][F]
        if len(F) == 0:
            F = np.array([[0, 1, 2]])
        out[f"random_{case:03d}"] = (V, F)
    return out


CHILD = r"""
import sys, warnings
import numpy as np
from meshshade.geometry.curvature import principal_curvatures
warnings.simplefilter("ignore")
data = np.load(sys.argv[1])
for name in sorted({k.rsplit("__", 1)[0] for k in data.files}):
    V, F = data[name + "__V"], data[name + "__F"]
    print("start", name, flush=True)
    try:
        c = principal_curvatures(V, F)
    except ValueError as exc:  # e.g. no non-degenerate faces: an error, not a crash
        print("refused", name, exc, flush=True)
        continue
    assert np.isfinite(c.k1).all() and np.isfinite(c.k2).all() and (c.k1 >= c.k2).all(), name
    assert np.isfinite(c.d1).all() and np.isfinite(c.d2).all(), name
    print("ok", name, c.n_fallback, c.n_no_plane, flush=True)
print("done", flush=True)
"""


def _run_in_child(tmp_path, meshes: dict) -> dict:
    path = tmp_path / "meshes.npz"
    np.savez(path, **{f"{k}__V": np.asarray(V, float) for k, (V, F) in meshes.items()},
             **{f"{k}__F": np.asarray(F, np.int64) for k, (V, F) in meshes.items()})
    proc = subprocess.run([sys.executable, "-c", CHILD, str(path)], capture_output=True, text=True, cwd=ROOT,
                          timeout=600)
    lines = proc.stdout.splitlines()
    started = [line.split()[1] for line in lines if line.startswith("start ")]
    assert proc.returncode == 0 and lines[-1:] == ["done"], (
        f"curvature fit died (exit {proc.returncode}) on {started[-1] if started else '?'}: {proc.stderr[-800:]}")
    return {parts[1]: (int(parts[2]), int(parts[3])) for parts in map(str.split, lines) if parts[0] == "ok"}


def test_odd_meshes_do_not_crash_the_curvature_fit(tmp_path):
    meshes = odd_meshes()
    counts = _run_in_child(tmp_path, meshes)
    assert set(counts) == set(meshes)
    # the vertices whose normals cancel are left out of libigl's fit and reported
    assert counts["bowtie_mirrored_tets"][1] >= 1 and counts["bowtie_octahedra"][1] >= 1
    assert counts["double_sided_grid"][1] == 36 and counts["octahedron"][1] == 6
    assert counts["flat_grid"] == (0, 0) and counts["bowtie_same_tets"][1] == 0


def test_random_odd_meshes_do_not_crash_the_curvature_fit(tmp_path):
    meshes = random_odd_meshes(120)
    counts = _run_in_child(tmp_path, meshes)
    assert len(counts) >= 100  # the rest were refused with an error (all faces degenerate), not crashed


# ------------------------------------------------------------------------------- the screen itself, in-process

def _screen(V, F, radius=2):
    """(vertices whose libigl fit plane is undefined, the faces that would go to libigl) for (V, F)."""
    V, F = np.asarray(V, float), np.asarray(F, np.int64)
    cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    faces, no_plane = curvature._faces_for_libigl(V, F, radius, cross, vertex_adjacency(len(V), F))
    return np.flatnonzero(no_plane).tolist(), faces


def test_screen_leaves_out_the_bowtie_vertex_only():
    V, F = _mirror_through(TET_V, TET_F, 0)
    flagged, faces = _screen(V, F)
    assert flagged == [0]
    np.testing.assert_array_equal(faces, F[~(F == 0).any(axis=1)])  # the two base triangles


@pytest.mark.parametrize("name", ["octahedron", "cube", "double_sided_grid", "thin_rod"])
def test_screen_flags_cancelling_neighbourhoods(name):
    V, F = odd_meshes()[name]
    flagged, faces = _screen(V, F)
    assert flagged and faces.shape[0] < len(F)


@pytest.mark.parametrize("shape", ["sphere", "torus", "flat_grid", "box"])
def test_screen_passes_ordinary_meshes_untouched(shape):
    V, F = {"sphere": procedural.icosphere(10.0, 3), "torus": procedural.torus(20.0, 5.0, 48, 16),
            "flat_grid": _grid(8), "box": procedural.box(10.0, 3)}[shape]
    flagged, faces = _screen(V, F)
    assert flagged == [] and faces is not None and faces.shape == np.asarray(F).shape


def test_heap_is_a_min_heap_on_distance(rng):
    d = rng.random(200)
    hd, hv = np.empty(200), np.empty(200, np.int64)
    size = 0
    for i, x in enumerate(d):
        size = curvature._heap_push(hd, hv, size, x, i)
    popped = []
    while size:
        popped.append(hv[0])
        size = curvature._heap_pop(hd, hv, size)
    np.testing.assert_array_equal(popped, np.argsort(d))


def test_ordinary_mesh_needs_no_fallback():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        clean = curvature.principal_curvatures(*procedural.icosphere(10.0, 3))
    assert clean.n_no_plane == 0 and clean.n_fallback == 0
