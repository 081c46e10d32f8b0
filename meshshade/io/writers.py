"""Small outputs and inputs: text, JSON, NPZ, figures, bytes, USD and OBJ written atomically; TOML, JSON and JSON
lines read.

Every writer goes through :func:`meshshade.io.transactions.atomic_write`. Writers refuse values a file cannot hold
(NaN, infinities, beyond float32: ``_check_float32``, which the PLY and EXR writers use too), and a full disk is
reported as such. Writers here: ``write_npz``, ``write_text`` (CSV tables), ``write_json``, ``write_figure``
(matplotlib, format from the extension), ``write_bytes``, ``write_usd`` and ``write_obj`` (every float64 exactly).
Readers: ``read_toml`` (a batch's job file), ``read_json``, ``read_json_lines`` (a batch manifest, which
``write_json_lines`` writes).
"""
from __future__ import annotations

import contextlib
import json
from pathlib import Path

import numpy as np

from meshshade.errors import MeshshadeError, OutputError
from meshshade.io._messages import _one_line
from meshshade.io.transactions import atomic_write, check_output_path

__all__ = ["write_npz", "write_text", "write_json", "write_figure", "read_toml", "read_json", "read_json_lines",
           "write_json_lines", "write_bytes", "write_usd", "write_obj"]

_FLOAT32_MAX = float(np.finfo(np.float32).max)


def _check_float32(path, what: str, values) -> None:
    """Refuse (``OutputError``) to write ``values`` that are NaN, infinite or beyond float32's range (which the
    file would store as infinity): an output file holds finite numbers or is not written."""
    v = np.asarray(values, dtype=np.float64)
    bad = ~(np.abs(v) <= _FLOAT32_MAX)
    if bad.any():
        raise OutputError(f"refusing to write {path}: {what} has {int(bad.sum())} value(s) that are not finite "
                          f"32-bit floats (first: {float(v[bad].flat[0])!r})")


def write_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8, e.g. a CSV table) atomically."""
    path = Path(path)
    with atomic_write(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def write_figure(path, figure, *, dpi: int = 150) -> Path:
    """Save a matplotlib ``figure`` atomically, in the format named by the extension (.png, .pdf, .svg, ...),
    then close it."""
    path = Path(path)
    fmt = path.suffix[1:].lower()
    supported = figure.canvas.get_supported_filetypes()
    if fmt not in supported:
        raise OutputError(f"unsupported figure format {path.suffix or '(no extension)'!r} for {path}; "
                          f"use one of {', '.join('.' + k for k in sorted(supported))}")
    try:
        with atomic_write(path) as tmp:
            figure.savefig(tmp, format=fmt, dpi=dpi, bbox_inches="tight")
    finally:
        import matplotlib.pyplot as plt  # lazy: heavy plotting library; already loaded by whoever made the figure

        plt.close(figure)
    return path


def write_npz(path, **arrays) -> Path:
    """Write arrays to a compressed ``.npz`` atomically (``numpy.savez_compressed`` into a temporary file)."""
    path = check_output_path(path, suffixes=(".npz",), option="NPZ output")
    with atomic_write(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
    return path


def write_bytes(path, data: bytes) -> Path:
    """Write ``data`` (a GLB, say) atomically."""
    path = Path(path)
    with atomic_write(path) as tmp:
        tmp.write_bytes(data)
    return path


def write_usd(path, stage) -> Path:
    """Write a ``Usd.Stage`` (:mod:`meshshade.output.usd`) atomically: ``.usda`` as text, ``.usd`` and ``.usdc`` as
    binary crate files (the temporary file keeps the extension, from which USD picks the format)."""
    path = Path(path)
    with atomic_write(path) as tmp:
        if not stage.GetRootLayer().Export(str(tmp)):
            raise OutputError(f"could not write {path}: USD refused to export the stage")
    return path


def write_json(path, obj) -> Path:
    """Write ``obj`` as indented JSON (UTF-8) atomically."""
    path = Path(path)
    with atomic_write(path) as tmp:
        tmp.write_text(json.dumps(obj, indent=2) + "\n", encoding="utf-8")
    return path


def read_toml(path) -> dict:
    """A TOML file (a batch's job file) as a dict; MeshshadeError with one line naming the file and the problem."""
    try:
        import tomllib
    except ModuleNotFoundError:  # pragma: no cover - Python 3.10
        import tomli as tomllib
    path = Path(path)
    if not path.is_file():
        raise MeshshadeError(f"job file not found: {path}" if not path.exists() else f"{path} is not a file")
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise MeshshadeError(f"{path}: not valid TOML: {exc}") from None
    except OSError as exc:
        raise MeshshadeError(f"cannot read {path}: {exc.strerror or _one_line(exc)}") from None


def read_json_lines(path) -> list[dict]:
    """The records of a JSON-lines file (a batch manifest); [] when it does not exist. A line that is not a JSON
    object (a torn last line) is skipped."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return []
    except OSError as exc:
        raise MeshshadeError(f"cannot read {path}: {exc.strerror or _one_line(exc)}") from None
    out = []
    for line in text.splitlines():
        with contextlib.suppress(ValueError):
            rec = json.loads(line)
            if isinstance(rec, dict):
                out.append(rec)
    return out


def write_json_lines(path, records) -> Path:
    """Write ``records`` (dicts) as JSON lines, atomically."""
    return write_text(path, "".join(json.dumps(r, sort_keys=True) + "\n" for r in records))


def read_json(path):
    """A JSON file's content, or None when it is missing or unreadable."""
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def write_obj(path, vertices, faces, *, uv=None, comment: str | None = None, groups=None) -> Path:
    """Write an OBJ (atomically) of ``vertices`` (n, 3), every float64 written exactly (17 significant digits, so
    :func:`load_mesh` reads back the same numbers), and 0-based triangle ``faces`` (m, 3); with ``uv`` (m, 3, 2)
    per-corner texture coordinates, each distinct (u, v) once as ``vt`` (in order of first use) and faces as
    ``f v/vt``. ``groups``: ``(names, face_group)``, part names (no blanks) and each face's index into them (m,):
    a ``usemtl NAME`` line wherever the part changes, the faces in their order (the parts
    :func:`~meshshade.io.read_face_names` reads)."""
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise ValueError(f"vertices and faces must be (n, 3) and (m, 3), got {V.shape} and {F.shape}")
    if uv is not None:
        uv = np.asarray(uv, dtype=np.float64)
        if uv.shape != (F.shape[0], 3, 2):
            raise ValueError(f"uv must be ({F.shape[0]}, 3, 2) per face corner, got {uv.shape}")
        table, first, inverse = np.unique(uv.reshape(-1, 2), axis=0, return_index=True, return_inverse=True)
        order = np.argsort(first, kind="stable")
        rank = np.empty_like(order)
        rank[order] = np.arange(order.size)
        T, TI = table[order], rank[inverse.reshape(-1)].reshape(-1, 3)
    runs = [(0, F.shape[0], None)]
    if groups is not None:
        names, part = list(groups[0]), np.asarray(groups[1], dtype=np.int64)
        if part.shape != (F.shape[0],) or (part.size and (part.min() < 0 or part.max() >= len(names))):
            raise ValueError(f"groups: one index into the {len(names)} names per face ({F.shape[0]}), got "
                             f"{part.shape}")
        if any(not n or any(ch.isspace() for ch in n) for n in names):
            raise ValueError(f"groups: part names must be non-empty and without blanks, got {names}")
        cut = np.flatnonzero(np.diff(part)) + 1
        starts = np.concatenate([[0], cut]).astype(np.int64)
        ends = np.concatenate([cut, [F.shape[0]]]).astype(np.int64)
        runs = [(int(a), int(b), names[part[a]]) for a, b in zip(starts, ends)] if F.shape[0] else runs
    path = check_output_path(path, suffixes=(".obj",), option="OBJ output")
    with atomic_write(path) as tmp:
        with open(tmp, "w", encoding="ascii") as fh:
            if comment:
                fh.write("".join(f"# {line}\n" for line in comment.splitlines()))
            np.savetxt(fh, V, fmt="v %.17g %.17g %.17g")
            if uv is not None:
                np.savetxt(fh, T, fmt="vt %.17g %.17g")
            for a, b, name in runs:
                if name is not None:
                    fh.write(f"usemtl {name}\n")
                if uv is None:
                    np.savetxt(fh, F[a:b] + 1, fmt="f %d %d %d")
                else:
                    np.savetxt(fh, np.stack([F[a:b] + 1, TI[a:b] + 1], axis=2).reshape(-1, 6),
                               fmt="f %d/%d %d/%d %d/%d")
    return path
