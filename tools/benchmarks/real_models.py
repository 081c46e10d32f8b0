"""The real models of issue 41 as users download them: their list (real_models.toml), where the files are, loading
one at its size in mm, and counting its defects.

The files themselves are not in the repository (licences, size, and CI has no network): they are fetched by hand
into ``shared/models/`` of the checkout (or ``../shared/models`` beside it, or ``$MESHSHADE_MODELS``) as
tools/benchmarks/README.md says; :func:`models_dir` is None without them and every benchmark or test that needs
them skips with that reason. Each entry of the list records its source (repository, path, commit, sha256),
licence, the scale to use (``mm_per_unit``: sizes 70-840 mm as in the issue) and the defects measured on it.

:func:`topology_counts` counts with plain numpy/scipy, independently of meshshade's own validation (which the
lead is changing): parts, open and non-manifold edges, duplicated, degenerate faces, unreferenced vertices.
"""
from __future__ import annotations

import hashlib
import os
import resource
import tomllib
import warnings
from pathlib import Path

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from meshshade.geometry.mesh import Mesh, nonmanifold_vertices
from meshshade.io import read_mesh_arrays

ROOT = Path(__file__).resolve().parents[2]
LIST = Path(__file__).with_name("real_models.toml")
REQUIRED = ("name", "file", "repository", "path", "commit", "sha256", "licence", "mm_per_unit", "size_mm", "kind",
            "defects", "note")


def models_dir() -> Path | None:
    """The folder holding the real models, or None when there is none (then skip, saying :func:`missing_reason`):
    ``$MESHSHADE_MODELS`` when set (and only it), else shared/models/ in the checkout, else ../shared/models/."""
    env = os.environ.get("MESHSHADE_MODELS")
    for folder in [Path(env)] if env else [ROOT / "shared" / "models", ROOT.parent / "shared" / "models"]:
        if folder.is_dir():
            return folder
    return None


def missing_reason() -> str:
    return ("the real models are not here (shared/models/ or ../shared/models/, or $MESHSHADE_MODELS): fetch them "
            "as tools/benchmarks/README.md says")


def entries(names=None) -> list[dict]:
    """The models of real_models.toml (all, or those named, in the list's order)."""
    with LIST.open("rb") as fh:
        models = tomllib.load(fh)["model"]
    if names is None:
        return models
    by_name = {m["name"]: m for m in models}
    unknown = [n for n in names if n not in by_name]
    if unknown:
        raise SystemExit(f"unknown model(s) {', '.join(unknown)}; choose among {', '.join(by_name)}")
    return [by_name[n] for n in names]


def url(entry: dict) -> str:
    """The file's address on GitHub at the recorded commit."""
    return f"https://github.com/{entry['repository']}/blob/{entry['commit']}/{entry['path']}"


def sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def model_path(entry: dict, folder: Path | None = None) -> Path | None:
    """The model's file, or None when it is not at hand."""
    folder = models_dir() if folder is None else folder
    if folder is None:
        return None
    path = folder / entry["file"]
    return path if path.is_file() else None


def load_arrays(entry: dict, folder: Path | None = None, *, check_sha: bool = True):
    """(vertices in mm, faces) of a model as its file has them (file order; polygons fan-triangulated by
    meshshade's reader), scaled by the entry's ``mm_per_unit``. Raises FileNotFoundError when absent and
    ValueError when the file is not the one recorded (sha256)."""
    path = model_path(entry, folder)
    if path is None:
        raise FileNotFoundError(f"{entry['file']}: {missing_reason()}")
    if check_sha and sha256(path) != entry["sha256"]:
        raise ValueError(f"{path}: sha256 differs from the one recorded in {LIST.name} (another version?)")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        V, F = read_mesh_arrays(path)
    return V * float(entry["mm_per_unit"]), F


def load_model(entry: dict, folder: Path | None = None, *, check_sha: bool = True) -> Mesh:
    """The model as a meshshade Mesh in mm (validated as a bake would; its defect warnings silenced)."""
    V, F = load_arrays(entry, folder, check_sha=check_sha)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Mesh.from_arrays(V, F, source=entry["file"])


def warm_up(material, lights) -> None:
    """Bake two small spheres, closed and with a hole, so that numba's kernels of the default bake and of its
    surface-transport fallback are compiled (or loaded from numba's cache) before a timed bake."""
    from meshshade.geometry.procedural import icosphere
    from meshshade.transport import bake

    V, F = icosphere(5.0, 2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bake(Mesh.from_arrays(V, F), material, lights)
        bake(Mesh.from_arrays(V, F[np.all(F != 0, axis=1)]), material, lights)


def reset_peak_rss() -> bool:
    """Reset this process's peak resident memory (Linux >= 4.0: ``/proc/self/clear_refs``, which resets both
    VmHWM and ``getrusage``'s ru_maxrss), so that a peak read after a bake is the bake's, not the warm-up's.
    False where it cannot (the peak then includes everything before)."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def peak_rss_mb() -> float:
    """Peak resident memory of this process in MB (1e6 bytes), from ``resource.getrusage`` (KiB on Linux)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e6


def cpu_seconds() -> float:
    """CPU seconds (user + system) this process has used so far: beside the wall time, a measure that a busy
    machine disturbs less (the bake's threads share 2 cores; on an idle machine wall >= CPU / 2)."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def topology_counts(vertices, faces) -> dict:
    """Defect counts of a triangle mesh (plain numpy/scipy, nothing repaired).

    Returns
    -------
    dict: ``vertices``, ``faces``; ``parts`` (connected components of the faces, by shared vertices);
    ``boundary_edges`` (used by one face), ``nonmanifold_edges`` (by three or more), ``nonmanifold_vertices``
    (bow-ties: several fans of faces meeting at a vertex only); ``duplicated_faces`` (faces whose corner set
    repeats an earlier face's, in either winding); ``degenerate_faces`` (a repeated corner, or zero area to
    1e-12 of the longest edge squared); ``unreferenced_vertices``; ``size`` (longest side of the bounding box of
    the referenced vertices) and ``mean_edge`` (units of ``vertices``).
    """
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    n = V.shape[0]
    proper = (F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])
    Fp = F[proper]
    e = np.sort(np.concatenate([Fp[:, [0, 1]], Fp[:, [1, 2]], Fp[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e[:, 0] * np.int64(n) + e[:, 1], return_counts=True)
    _, dup_counts = np.unique(np.sort(F, axis=1), axis=0, return_counts=True)
    cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    edges = np.stack([V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 1]], V[F[:, 0]] - V[F[:, 2]]], axis=1)
    lengths = np.linalg.norm(edges, axis=2)
    degenerate = ~proper | (np.linalg.norm(cross, axis=1) <= 1e-12 * lengths.max(axis=1) ** 2)
    used = np.zeros(n, dtype=bool)
    used[F.reshape(-1)] = True
    rows = np.concatenate([F[:, 0], F[:, 1]])
    cols = np.concatenate([F[:, 1], F[:, 2]])
    graph = sparse.coo_matrix((np.ones(rows.size, np.int8), (rows, cols)), shape=(n, n))
    _, labels = csgraph.connected_components(graph, directed=False)
    return {"vertices": int(n), "faces": int(F.shape[0]), "parts": int(np.unique(labels[used]).size),
            "boundary_edges": int(np.count_nonzero(counts == 1)),
            "nonmanifold_edges": int(np.count_nonzero(counts > 2)),
            "nonmanifold_vertices": int(np.count_nonzero(nonmanifold_vertices(n, F))),
            "duplicated_faces": int((dup_counts - 1).sum()), "degenerate_faces": int(degenerate.sum()),
            "unreferenced_vertices": int(np.count_nonzero(~used)),
            "size": float(np.ptp(V[used], axis=0).max()), "mean_edge": float(lengths.mean())}
