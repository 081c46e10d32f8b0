"""Long runs: progress on stderr (a tqdm bar on a terminal, one-line messages in a pipe or a log) and Ctrl-C.

:class:`Progress` is what ``bake`` (and the bakes of ``render`` and ``compare``) and ``mc`` report their work
through (``progress=True`` or a task name in :func:`meshshade.transport.baking.bake` and
:func:`meshshade.montecarlo.simulation.simulate`; the CLI passes it unless ``--quiet``):

* on a terminal, a tqdm bar that clears itself when done;
* otherwise (stderr redirected to a file or a pipe) nothing for short jobs, and for long ones one line per
  :data:`DEFAULT_INTERVAL` seconds (``MESHSHADE_PROGRESS_INTERVAL`` in the environment, or ``interval=``) and at
  25, 50 and 75 %::

      meshshade: bake: estimated 12 min
      meshshade: bake: 25 % (2560/10242 sources), 3:02 elapsed, ~9:06 left

  The estimate line comes once, as soon as :data:`ESTIMATE_AFTER` seconds or :data:`ESTIMATE_FRACTION` of the
  work are done, if the whole job is projected to take more than :data:`LONG_JOB` seconds; the 25/50/75 %
  lines only in a job that long (or one already past its first interval). The time left is projected from the
  speed since the first update (numba compiling its kernels on a first run is left out). Every line starts
  with ``meshshade: <task>:``.

Time comes from ``clock`` (default :func:`time.monotonic`), so tests drive it with a fake clock.

Ctrl-C: Python acts on a signal only between bytecodes, so long computations are cut into calls of a few
tenths of a second (:func:`meshshade.pacing.run_paced`). A signal that arrives while
a compiled loop runs in the main thread is acted upon when numba converts the loop's results, which numba
reports as a ``SystemError``; :func:`kernel_interrupts` (around such calls) and :func:`interrupt_in` (for a
command-line front end) recover the KeyboardInterrupt.

:class:`Stopwatch` times a run's stages (a bake's ``timings``).
"""
from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
import warnings

from tqdm import tqdm

__all__ = ["Progress", "Stopwatch", "DEFAULT_INTERVAL", "INTERVAL_ENV", "format_duration", "interrupt_in",
           "kernel_interrupts", "polled_interrupts"]

#: seconds between two progress lines when stderr is not a terminal
DEFAULT_INTERVAL = 30.0
#: environment variable overriding :data:`DEFAULT_INTERVAL` (seconds, >= 0)
INTERVAL_ENV = "MESHSHADE_PROGRESS_INTERVAL"
#: fractions of the work at which a line is printed (in long jobs)
MILESTONES = (0.25, 0.5, 0.75)
#: the up-front estimate is made after this many seconds or this fraction of the work, whichever comes first
ESTIMATE_AFTER = 5.0
ESTIMATE_FRACTION = 0.03
#: a job projected to take longer than this many seconds gets the estimate line and the milestone lines
LONG_JOB = 60.0


def format_duration(seconds: float) -> str:
    """``m:ss`` below an hour, ``h:mm:ss`` above."""
    s = int(round(max(seconds, 0.0)))
    h, rest = divmod(s, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


def _rough_duration(seconds: float) -> str:
    """A projected duration as a person would say it: ``45 s``, ``12 min``, ``2.5 h``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 2 * 3600:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def _interval_from_env() -> float:
    text = os.environ.get(INTERVAL_ENV)
    if text is None or not text.strip():
        return DEFAULT_INTERVAL
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value >= 0 or value == float("inf"):
        warnings.warn(f"{INTERVAL_ENV}={text!r} is not a number of seconds >= 0; progress lines every "
                      f"{DEFAULT_INTERVAL:g} s", stacklevel=3)
        return DEFAULT_INTERVAL
    return value


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):  # no isatty, or a closed stream
        return False


class Progress:
    """Work done out of ``total`` (None: unknown) ``unit``\\ s of one ``task``, reported on ``stream``.

    ``enabled`` False: silent (``--quiet``). ``stream`` defaults to ``sys.stderr`` at creation; ``tty``
    (default: ``stream.isatty()``) chooses the tqdm bar or the lines; ``interval`` (seconds) defaults to
    ``MESHSHADE_PROGRESS_INTERVAL`` or :data:`DEFAULT_INTERVAL`. :meth:`update` takes fractional amounts (a
    part of a chunk of sources); :meth:`close` (or leaving a ``with`` block) clears the bar. Nothing is printed
    at the end: the command's own summary follows.
    """

    def __init__(self, task: str, total: float | None = None, unit: str = "", *, enabled: bool = True,
                 stream=None, tty: bool | None = None, interval: float | None = None, clock=time.monotonic):
        self.task, self.total, self.unit, self.enabled = task, total, unit, bool(enabled)
        self.stream = sys.stderr if stream is None else stream
        self.clock = clock
        self.n = 0.0
        self.lines: list[str] = []  # every line printed (for tests and logs)
        self.stage: str | None = None  # the stage now running, for a job made of stages (set_stage)
        self._bar = None
        self._tty = False
        if not self.enabled:
            return
        self._tty = _is_terminal(self.stream) if tty is None else bool(tty)
        self.interval = _interval_from_env() if interval is None else float(interval)
        self._t0 = self._last = clock()
        self._milestones = list(MILESTONES)
        self._estimated = False  # the estimate line was printed
        self._long = False  # projected or seen to take longer than LONG_JOB
        self._ref = None  # (time, units done) at the first update
        if self._tty:
            self._bar = tqdm(total=total, desc=task, unit=unit, leave=False, file=self.stream, disable=False)

    # -- reporting ---------------------------------------------------------------------------------------------
    def update(self, amount: float = 1) -> None:
        """``amount`` more units done."""
        if not self.enabled or amount == 0:
            return
        before = self.n
        self.n += amount
        if self._bar is not None:
            step = int(self.n) - int(before)
            if step:
                self._bar.update(step)
            return
        now = self.clock()
        if self._ref is None:  # the speed is measured from the first update on (not the start-up before it)
            self._ref = (now, self.n)
        frac = self.fraction
        if (not self._estimated and frac is not None and 0 < frac < MILESTONES[0] and self.n > self._ref[1]
                and (now - self._t0 >= ESTIMATE_AFTER or frac >= ESTIMATE_FRACTION)):
            projected = now - self._t0 + self.seconds_left(now)
            if projected > LONG_JOB:
                self._long = self._estimated = True
                self._emit(f"estimated {_rough_duration(projected)}", now)
        line = now - self._last >= self.interval
        if line:
            self._long = True
        if frac is not None and self._milestones and frac >= self._milestones[0]:
            while self._milestones and frac >= self._milestones[0]:
                self._milestones.pop(0)
            line = line or self._long
        if line:
            self._emit(self.status(now), now)

    def set_stage(self, name: str) -> None:
        """Name the stage now running: the bar's label on a terminal, ``[name]`` after the status in lines."""
        self.stage = name
        if self._bar is not None:
            self._bar.set_description(f"{self.task}: {name}", refresh=True)

    def seconds_left(self, now: float | None = None) -> float:
        """Projected seconds to the end (inf while unknown): the work left at the speed since the first update
        (or since the start when that is all there is)."""
        if self.total is None:
            return float("inf")
        now = self.clock() if now is None else now
        left = max(self.total - self.n, 0.0)
        t_ref, n_ref = self._ref if self._ref is not None else (self._t0, 0.0)
        if self.n <= n_ref or now <= t_ref:
            t_ref, n_ref = self._t0, 0.0
        if self.n <= n_ref or now <= t_ref:
            return 0.0 if left == 0 else float("inf")
        return left * (now - t_ref) / (self.n - n_ref)

    @property
    def fraction(self) -> float | None:
        """Fraction of the work done, None when the total is unknown."""
        if not self.total or self.total <= 0:
            return None
        return min(1.0, self.n / self.total)

    def status(self, now: float | None = None) -> str:
        """The progress line without its ``meshshade: task:`` prefix."""
        now = self.clock() if now is None else now
        elapsed = now - self._t0
        frac = self.fraction
        unit = f" {self.unit}" if self.unit else ""
        stage = f" [{self.stage}]" if self.stage else ""
        if frac is None:
            return f"{int(self.n)}{unit}, {format_duration(elapsed)} elapsed{stage}"
        remaining = self.seconds_left(now)
        left = f", ~{format_duration(remaining)} left" if remaining < float("inf") else ""
        return (f"{int(100 * frac)} % ({int(self.n)}/{int(self.total)}{unit}), {format_duration(elapsed)} elapsed"
                f"{left}{stage}")

    def _emit(self, text: str, now: float) -> None:
        line = f"meshshade: {self.task}: {text}"
        self.lines.append(line)
        self._last = now
        try:
            print(line, file=self.stream, flush=True)
        except (OSError, ValueError):  # stderr gone (closed pipe, full disk): progress is not worth failing for
            self.enabled = False

    # -- life cycle --------------------------------------------------------------------------------------------
    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# ------------------------------------------------------------------------------------------------ interrupts
def interrupt_in(exc: BaseException | None) -> KeyboardInterrupt | None:
    """The KeyboardInterrupt (Ctrl-C, or SIGTERM/SIGHUP in the CLI) that ``exc`` is or hides, else None.

    numba converts a kernel's array results to Python objects with a call into Python; a signal that arrived
    while the kernel ran is acted upon in that call, and numba then reports the KeyboardInterrupt as a
    ``SystemError`` ("... returned a result with an exception set") caused by it."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


@contextlib.contextmanager
def kernel_interrupts():
    """Around compiled loop calls made in the main thread: an interrupt that numba reports as a SystemError
    (:func:`interrupt_in`) is raised as the KeyboardInterrupt it is; any other error as it is."""
    try:
        yield
    except SystemError as exc:
        interrupt = interrupt_in(exc)
        if interrupt is None:
            raise
        raise interrupt from None


#: the signals that stop a run (as the CLI's)
_STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n))


@contextlib.contextmanager
def polled_interrupts():
    """Inside the block, SIGINT, SIGTERM and SIGHUP only note themselves; the ``poll()`` it yields raises the
    interrupt (through the handler installed before: KeyboardInterrupt, or the CLI's SIGTERM/SIGHUP exception)
    where the caller calls it, and leaving the block raises one that arrived after the last poll.

    For a thread that waits on worker threads: a KeyboardInterrupt raised at an arbitrary bytecode can land
    while the waiting thread holds a lock of ``threading`` or ``concurrent.futures`` (``wait`` takes every
    future's lock, ``submit`` the pool's semaphore) and leave it held, and the workers then block on it forever
    (seen: 1 render in ~60 froze after Ctrl-C). Polled, the interrupt is raised between those calls. Outside the
    main thread (where Python runs no signal handlers) the block runs as it is and ``poll()`` does nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield lambda: None
        return
    noted: list = []

    def note(signum, frame):
        noted.append(signum)

    previous = {s: signal.signal(s, note) for s in _STOP_SIGNALS}

    def deliver(signum):
        handler = previous[signum]
        if callable(handler):
            handler(signum, None)
        elif handler == signal.SIG_DFL:
            if signum == signal.SIGINT:
                raise KeyboardInterrupt
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)

    def poll():
        if noted:
            signum = noted[0]
            noted.clear()
            deliver(signum)

    try:
        yield poll
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    if noted:
        deliver(noted[0])


class Stopwatch:
    """Wall time per stage: :meth:`lap` charges the time since the previous lap to a stage (seconds, summed)."""

    def __init__(self):
        self.timings: dict = {}
        self._t0 = time.perf_counter()

    def lap(self, name: str) -> None:
        t = time.perf_counter()
        self.timings[name] = self.timings.get(name, 0.0) + t - self._t0
        self._t0 = t

    def charge(self, timings: dict) -> None:
        """Add stage times measured elsewhere (``{stage: seconds}``) and restart the lap there."""
        for name, seconds in timings.items():
            self.timings[name] = self.timings.get(name, 0.0) + seconds
        self._t0 = time.perf_counter()
