"""A bake that runs beside Blender: ``meshshade bake`` in a child process, watched and cancellable (no ``bpy``).

Blender's interface runs in one thread. A bake there would freeze it, and numba's kernels cannot be interrupted
from another thread; a child process can be stopped at once. :class:`BakeJob` writes the world-space mesh (mm,
float64 exact: :func:`meshshade.io.write_obj`) into a private folder, runs the command-line bake on it once per
light colour (:func:`meshshade.blender.convert.colour_groups`), reads its progress lines, and sums the groups'
exitance weighted by their colours. The command is the same ``meshshade bake`` a user would run, so the add-on's
result is the CLI's to float precision. ``python`` (default: the running interpreter, Blender's own) may be
another environment with meshshade installed (the add-on's preference "Python for bakes"). With ``texture_size``
(and the UV map ``uv``, per corner) each run also bakes a texture (``meshshade bake --texture``) and
:attr:`BakeJob.texture` is their colour-weighted sum.

:meth:`BakeJob.poll` never blocks (the add-on calls it from a timer); :meth:`BakeJob.cancel` stops the child
(SIGINT, then SIGKILL after :data:`CANCEL_GRACE` s) and removes the folder; :meth:`BakeJob.wait` runs it to the
end (scripts, background mode).
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from meshshade import io
from meshshade.names import DEFAULT_MODEL
from meshshade.errors import MeshshadeError
from meshshade.light.sources import AreaLight, BeamLight, DirectionalLight, EnvironmentLight, PointLight

__all__ = ["BakeSettings", "BakeJob", "BakeJobError", "light_spec", "CANCEL_GRACE"]

#: seconds a cancelled child gets to clean up after SIGINT before it is killed
CANCEL_GRACE = 3.0
#: seconds between the child's progress lines
PROGRESS_INTERVAL = 0.5
_PERCENT = re.compile(r"meshshade: [^:]+: (\d+) % ")
_PROBLEM = re.compile(r"^meshshade: (error|warning): (.*)$")


class BakeJobError(MeshshadeError):
    """The child bake failed: one line, the command's own error message where it gave one."""


def _num(x: float) -> str:
    return repr(float(x))   # the shortest text that reads back as the same float64


def _vec(v) -> str:
    return ",".join(_num(x) for x in v)


def light_spec(light) -> str:
    """The ``--light`` text of a meshshade light (positions in mm, numbers exact)."""
    if isinstance(light, DirectionalLight):
        return f"directional:{_vec(light.direction)}:{_num(light.irradiance)}"
    if isinstance(light, PointLight):
        if light.spot is None:
            return f"point:{_vec(light.position)}:{_num(light.intensity)}"
        sp = light.spot
        return (f"spot:{_vec(light.position)}:{_vec(sp.axis)}:{_num(light.intensity)}:"
                f"{_num(np.degrees(sp.angle))}:{_num(sp.blend)}")
    if isinstance(light, BeamLight):
        return f"beam:{_vec(light.origin)}:{_vec(light.direction)}:{_num(light.power)}:{_num(light.radius)}"
    if isinstance(light, EnvironmentLight):
        if light.path is not None:
            return f"env:{light.path}:{_num(light.strength)}:{_num(light.rotation_deg)}:{light.up}"
        if light.is_uniform:
            return f"uniform:{_num(light.strength * float(light.radiance.max()))}"
        raise MeshshadeError("an environment map given as an array has no --light spec (write it to an EXR file)")
    if isinstance(light, AreaLight):
        up = "" if light.up is None else f":{_vec(light.up)}"
        return (f"area:{_vec(light.position)}:{_vec(light.normal)}:{light.shape}:{_vec(light.size)}:"
                f"{_num(light.power)}{up}")
    raise MeshshadeError(f"not a meshshade light: {light!r}")


@dataclass
class BakeSettings:
    """The bake's options (the add-on panel's settings): a ``preset`` name, or ``sigma_s_prime`` and ``sigma_a``
    (RGB, 1/mm) with ``eta``; ``model``, ``cutoff_tol``, ``geodesic``, ``transport`` as ``meshshade bake``;
    ``albedo_map``: a colour map over the mesh's UVs painting the medium (``--albedo-map``; the job then needs
    ``uv``), its colours that no medium reflects moved into the reachable range with ``albedo_clamp``
    (``--albedo-clamp``, noted); ``radius_map``: a map over the UVs scaling the mean free path (``--radius-map``,
    eq. (132); the job then needs ``uv``); ``parts``: ``((name, sigma_s_prime, sigma_a), ...)``, the media of the
    faces a
    :class:`BakeJob`'s ``face_part`` gives to each (``--material NAME=SIGMA_S_PRIME/SIGMA_A``, one index ``eta``
    for all), the material above the rest."""

    preset: str | None = "skin1"
    sigma_s_prime: tuple = (1.0, 1.0, 1.0)
    sigma_a: tuple = (0.01, 0.01, 0.01)
    eta: float = 1.3
    model: str = DEFAULT_MODEL
    cutoff_tol: float = 1e-4
    geodesic: str = "exact"
    transport: str = "auto"
    albedo_map: str | None = None
    albedo_clamp: bool = True
    radius_map: str | None = None
    parts: tuple = ()

    def cli_args(self) -> list[str]:
        """The options of ``meshshade bake`` these settings stand for."""
        if self.preset:
            material = ["--material", self.preset]
        else:
            material = ["--sigma-s-prime", _vec(self.sigma_s_prime), "--sigma-a", _vec(self.sigma_a),
                        "--eta", _num(self.eta)]
        for name, ss, sa in self.parts:
            material += ["--material", f"{name}={_vec(ss)}/{_vec(sa)}"]
        if self.albedo_map:
            material += ["--albedo-map", str(self.albedo_map)] + (["--albedo-clamp"] if self.albedo_clamp else [])
        if self.radius_map:
            material += ["--radius-map", str(self.radius_map)]
        return material + ["--model", self.model, "--cutoff-tol", _num(self.cutoff_tol), "--geodesic",
                           self.geodesic, "--transport", self.transport]


@dataclass
class _Run:
    colour: np.ndarray
    args: list
    npz: Path
    exr: Path | None = None
    proc: subprocess.Popen | None = None
    lines: list = field(default_factory=list)
    reader: threading.Thread | None = None


class BakeJob:
    """One bake of ``vertices`` (mm) and ``faces`` under ``groups`` = ``[(colour (3,), [lights]), ...]``.

    Call :meth:`start`, then :meth:`poll` until it returns True (or :meth:`wait`); then :attr:`radiance` (n, 3)
    float64 W/mm^2 is the colour-weighted sum, :attr:`warnings` the bake's warning lines, :attr:`summary` its
    report. A failure raises :class:`BakeJobError` from :meth:`poll` / :meth:`wait` with the command's one-line
    error. ``python``: the interpreter that runs ``meshshade`` (default: this one). ``log``: a file that receives
    every child's output (for a failure that is not a user mistake). ``texture_size``: also bake a texture of that
    many texels per side over the per-corner UV map ``uv`` (m, 3, 2) with ``padding``; :attr:`texture` (H, W, 4)
    float64 is then the colour-weighted exitance (RGB, W/mm^2; row 0 the top, v = 1) and the coverage (A).
    ``face_part`` (m,) int, with ``settings.parts``: each face's part (-1: the settings' material), written as the
    mesh's ``usemtl`` names that ``--material NAME=...`` reads.
    """

    def __init__(self, vertices, faces, groups, settings: BakeSettings, *, python: str | None = None,
                 log: str | os.PathLike | None = None, uv=None, texture_size: int | None = None,
                 padding: int = 16, face_part=None):
        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.int64)
        self.groups = groups
        self.settings = settings
        self.python = python or sys.executable
        self.log = Path(log) if log else None
        self.fraction = 0.0
        self.message = "starting"
        self.radiance: np.ndarray | None = None
        self.uv = None if uv is None else np.asarray(uv, dtype=np.float64)
        self.texture_size, self.padding = texture_size, int(padding)
        needs_uv = texture_size is not None or settings.albedo_map or settings.radius_map
        if needs_uv and (self.uv is None or self.uv.shape != (self.faces.shape[0], 3, 2)):
            raise BakeJobError(("a texture bake" if texture_size is not None else
                                "a colour map (albedo map)" if settings.albedo_map else "a radius map")
                               + " needs a UV map: one (u, v) per face corner")
        self.face_part = None
        if settings.parts:
            fp = None if face_part is None else np.asarray(face_part, dtype=np.int64)
            if fp is None or fp.shape != (self.faces.shape[0],) or fp.min() < -1 or fp.max() >= len(settings.parts):
                raise BakeJobError(f"parts of {len(settings.parts)} media need each face's part: -1 for the rest, "
                                   "else an index into the parts")
            self.face_part = fp
        self.texture: np.ndarray | None = None
        self._texture_sum: np.ndarray | None = None
        self.warnings: list[str] = []
        self.summary: list[str] = []
        self.cancelled = False
        self._dir: Path | None = None
        self._runs: list[_Run] = []
        self._current = -1
        self._sum: np.ndarray | None = None

    # -- life cycle ----------------------------------------------------------------------------------------
    def start(self) -> "BakeJob":
        if not self.groups:
            raise BakeJobError("no lights to bake")
        if not Path(self.python).exists():
            raise BakeJobError(f"the Python for bakes does not exist: {self.python}")
        self._dir = io.scratch_folder("meshshade-blender-")
        textured = self.texture_size is not None
        with_uv = textured or bool(self.settings.albedo_map) or bool(self.settings.radius_map)
        groups = None
        if self.face_part is not None:     # each part a usemtl of its own, the rest "rest"
            groups = (["rest", *(name for name, _ss, _sa in self.settings.parts)], self.face_part + 1)
        mesh = io.write_obj(self._dir / "mesh.obj", self.vertices, self.faces, uv=self.uv if with_uv else None,
                            comment="meshshade: world-space mesh in mm, written by the Blender add-on",
                            groups=groups)
        for k, (colour, lights) in enumerate(self.groups):
            npz = self._dir / f"group{k}.npz"
            exr = self._dir / f"group{k}.exr" if textured else None
            args = ["-m", "meshshade.cli", "bake", str(mesh), "--units", "mm", *self.settings.cli_args(),
                    *[a for lt in lights for a in ("--light", light_spec(lt))],
                    "--out", str(self._dir / f"group{k}.ply"), "--npz", str(npz)]
            if textured:
                args += ["--texture", str(exr), "--texture-size", str(int(self.texture_size)),
                         "--padding", str(self.padding)]
            self._runs.append(_Run(np.asarray(colour, dtype=np.float64), args, npz, exr))
        self._sum = np.zeros((self.vertices.shape[0], 3))
        self._next()
        return self

    def _next(self) -> None:
        self._current += 1
        run = self._runs[self._current]
        env = dict(os.environ, MESHSHADE_PROGRESS_INTERVAL=str(PROGRESS_INTERVAL), PYTHONUNBUFFERED="1")
        run.proc = subprocess.Popen([self.python, *run.args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                    stdin=subprocess.DEVNULL, text=True, env=env, cwd=self._dir,
                                    start_new_session=True)   # Ctrl-C in Blender's terminal is not the child's
        run.reader = threading.Thread(target=self._read, args=(run,), daemon=True)
        run.reader.start()
        self.message = self._stage("starting")

    @staticmethod
    def _read(run: _Run) -> None:
        for line in run.proc.stdout:
            run.lines.append(line.rstrip("\n"))

    def _stage(self, text: str) -> str:
        n = len(self._runs)
        return f"bake {self._current + 1}/{n}: {text}" if n > 1 else f"bake: {text}"

    def poll(self) -> bool:
        """True when done (the result is ready); raises BakeJobError when the bake failed."""
        if self.radiance is not None:
            return True
        if self._current < 0 or self.cancelled:
            raise BakeJobError("the bake was not started" if not self.cancelled else "the bake was cancelled")
        run = self._runs[self._current]
        for line in reversed(run.lines):
            m = _PERCENT.search(line)
            if m:
                part = int(m.group(1)) / 100.0
                self.fraction = (self._current + part) / len(self._runs)
                self.message = self._stage(f"{m.group(1)} %")
                break
        if run.proc.poll() is None:
            return False
        run.reader.join()
        self._log(run)
        if run.proc.returncode != 0:
            problem = [m.group(2) for m in map(_PROBLEM.match, run.lines) if m and m.group(1) == "error"]
            text = problem[-1] if problem else (run.lines[-1] if run.lines else "no output")
            self._cleanup()
            raise BakeJobError(f"the bake failed (exit {run.proc.returncode}): {text}"
                               + ("" if problem or not self.log else f"; details in {self.log}"))
        self.warnings += [m.group(2) for m in map(_PROBLEM.match, run.lines) if m and m.group(1) == "warning"]
        self.summary += [ln for ln in run.lines if not ln.startswith("meshshade: ")]
        with np.load(run.npz) as z:
            self._sum += run.colour * np.asarray(z["radiance"], dtype=np.float64)
        if run.exr is not None:
            pixels, _ = io.read_exr(run.exr)
            pixels = np.asarray(pixels, dtype=np.float64)
            if self._texture_sum is None:
                self._texture_sum = np.zeros(pixels.shape[:2] + (4,))
                self._texture_sum[..., 3] = pixels[..., 3]
            self._texture_sum[..., :3] += run.colour * pixels[..., :3]
        if self._current + 1 < len(self._runs):
            self._next()
            return False
        self.radiance, self.fraction, self.message = self._sum, 1.0, "done"
        self.texture = self._texture_sum
        self._cleanup()
        return True

    def wait(self, on_progress=None, interval: float = 0.1) -> np.ndarray:
        """Run to the end (``on_progress(fraction, message)`` on the way); the radiance."""
        if self._current < 0:
            self.start()
        try:
            while not self.poll():
                if on_progress is not None:
                    on_progress(self.fraction, self.message)
                time.sleep(interval)
        except KeyboardInterrupt:
            self.cancel()
            raise
        return self.radiance

    def cancel(self) -> None:
        """Stop the child (SIGINT so it removes its partial files, SIGKILL after CANCEL_GRACE s); remove the
        folder."""
        self.cancelled = True
        if 0 <= self._current < len(self._runs):
            proc = self._runs[self._current].proc
            if proc is not None and proc.poll() is None:
                try:
                    os.killpg(proc.pid, signal.SIGINT) if hasattr(os, "killpg") else proc.send_signal(signal.SIGINT)
                    proc.wait(timeout=CANCEL_GRACE)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
                except ProcessLookupError:
                    pass
        self._cleanup()

    @property
    def running(self) -> bool:
        return self._current >= 0 and self.radiance is None and not self.cancelled

    # -- helpers -------------------------------------------------------------------------------------------
    def _log(self, run: _Run) -> None:
        if self.log is None:
            return
        io.append_text(self.log, " ".join([self.python, *run.args]) + "\n" + "\n".join(run.lines) + "\n")

    def _cleanup(self) -> None:
        if self._dir is not None:
            io.remove_folder(self._dir)
            self._dir = None

    def __del__(self):  # a job dropped while running (Blender closed): stop the child, leave nothing behind
        try:
            if self.running:
                self.cancel()
            self._cleanup()
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass
