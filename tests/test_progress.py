"""Long runs: progress and Ctrl-C (issue 17).

* meshshade.progress: the lines written when stderr is not a terminal (estimate, periodic, 25/50/75 %), quiet,
  the terminal bar, driven by a fake clock (no sleeps); bake and mc report through it;
* interrupts: a signal during a compiled loop in the main thread is the KeyboardInterrupt it is, not numba's
  SystemError (a real kernel and a real signal, synchronised on the kernel's own flag); the geodesic queries
  run in paced blocks (meshshade.pacing.run_paced) whose queued part an interrupt
  cancels, and whose boundaries never change a result.
"""
from __future__ import annotations

import io
import os
import re
import signal
import threading
import time

import numpy as np
import pytest
from numba import njit

from meshshade import progress as P
from meshshade.geometry.geodesics import neighbourhoods as NB
from meshshade.geometry.geodesics.arc import ArcGeodesicNeighbourhoods
from meshshade.geometry.geodesics.neighbourhoods import GeodesicNeighbourhoods
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.light import parse_light_spec
from meshshade.materials import material_from_options
from meshshade.montecarlo.simulation import simulate
from meshshade.pacing import BLOCK_SECONDS, Pacer, default_threads, run_in_blocks, run_paced
from meshshade.progress import Progress, format_duration, interrupt_in, kernel_interrupts
from meshshade.transport.baking import bake
from meshshade.montecarlo import MCOptions
from meshshade.transport import BakeOptions, SurfaceOptions

LINE = re.compile(r"^meshshade: bake: \d+ % \(\d+/\d+ sources\), \d+:\d\d elapsed, ~\d+:\d\d left$")


class Clock:
    def __init__(self):
        self.t = 1000.0

    def __call__(self):
        return self.t


def _progress(total=1000, interval=30.0, **kw):
    clock, out = Clock(), io.StringIO()
    return Progress("bake", total, "sources", stream=out, tty=False, interval=interval, clock=clock, **kw), clock, out


def _lines(out):
    return out.getvalue().splitlines()


def test_long_job_estimate_periodic_and_milestone_lines():
    """Ten minutes for 1000 sources at a steady speed, one update per second, lines every 100 s: one estimate
    line once the speed is measured (the first update ends a start-up of 20 s that the speed leaves out), a line
    100 s after the previous one, and the 25/50/75 % lines; each one line starting with "meshshade: bake:"."""
    p, clock, out = _progress(interval=100.0)
    clock.t += 20.0  # start-up (numba compiling) before the first block
    p.update(2)
    for _ in range(600):
        clock.t += 1.0
        p.update(998 / 600)
    assert _lines(out) == p.lines == [
        "meshshade: bake: estimated 10 min",
        "meshshade: bake: 16 % (169/1000 sources), 2:01 elapsed, ~8:19 left",
        "meshshade: bake: 25 % (251/1000 sources), 2:50 elapsed, ~7:30 left",
        "meshshade: bake: 41 % (417/1000 sources), 4:30 elapsed, ~5:50 left",
        "meshshade: bake: 50 % (501/1000 sources), 5:20 elapsed, ~5:00 left",
        "meshshade: bake: 66 % (667/1000 sources), 7:00 elapsed, ~3:20 left",
        "meshshade: bake: 75 % (750/1000 sources), 7:50 elapsed, ~2:30 left",
        "meshshade: bake: 91 % (916/1000 sources), 9:30 elapsed, ~0:50 left"]
    assert all(LINE.match(line) for line in p.lines[1:])


def test_short_job_prints_nothing():
    """A job of 20 s (projected below LONG_JOB): no estimate, no milestone lines, no periodic line."""
    p, clock, out = _progress()
    for _ in range(100):
        clock.t += 0.2
        p.update(10)
    p.close()
    assert out.getvalue() == ""


def test_estimate_waits_for_a_measured_speed_and_comes_once():
    """The first update carries the start-up, so no estimate from it alone; then exactly one estimate."""
    p, clock, out = _progress(total=800, interval=1e9)
    clock.t += 10.0
    p.update(40)  # 5 % after 10 s: a speed that includes the start-up, not yet an estimate
    assert out.getvalue() == ""
    clock.t += 1.0
    p.update(10)  # 10 units per second since the first update: 750 left -> 75 s, plus 11 s elapsed
    assert _lines(out) == ["meshshade: bake: estimated 86 s"]
    for _ in range(5):
        clock.t += 1.0
        p.update(10)
    assert len(_lines(out)) == 1


def test_quiet_is_silent_and_free():
    p, clock, out = _progress(enabled=False)
    for _ in range(100):
        clock.t += 100.0
        p.update(10)
    p.close()
    assert out.getvalue() == "" and p.lines == []


def test_unknown_total_reports_the_count():
    """Monte Carlo under a time budget: no total, so no percentages and no estimate, only the count."""
    clock, out = Clock(), io.StringIO()
    p = Progress("mc", None, "photons", stream=out, tty=False, interval=10.0, clock=clock)
    for _ in range(25):
        clock.t += 1.0
        p.update(1000)
    assert _lines(out) == ["meshshade: mc: 10000 photons, 0:10 elapsed", "meshshade: mc: 20000 photons, 0:20 elapsed"]


def test_interval_from_the_environment(monkeypatch):
    monkeypatch.setenv(P.INTERVAL_ENV, "0")
    clock, out = Clock(), io.StringIO()
    p = Progress("bake", 4, "sources", stream=out, tty=False, clock=clock)
    for _ in range(4):
        clock.t += 0.5
        p.update(1)
    assert len(_lines(out)) == 4  # interval 0: a line per update
    monkeypatch.setenv(P.INTERVAL_ENV, "soon")
    with pytest.warns(UserWarning, match=P.INTERVAL_ENV):
        assert Progress("bake", 4, stream=out, tty=False).interval == P.DEFAULT_INTERVAL


def test_terminal_gets_a_bar_not_lines():
    """On a terminal tqdm draws (carriage returns) and closes; fractional updates show whole units."""
    clock, out = Clock(), io.StringIO()
    with Progress("bake", 10, "sources", stream=out, tty=True, interval=0.0, clock=clock) as p:
        for _ in range(20):
            clock.t += 100.0
            p.update(0.5)
        assert p._bar.n == 10
    assert p.lines == [] and "\r" in out.getvalue() and "meshshade:" not in out.getvalue()


def test_closed_stream_stops_reporting():
    clock, out = Clock(), io.StringIO()
    p = Progress("bake", 10, stream=out, tty=False, interval=0.0, clock=clock)
    out.close()
    clock.t += 1.0
    p.update(1)  # no exception: progress is never worth failing a job for
    assert not p.enabled


@pytest.mark.parametrize("seconds, text", [(0, "0:00"), (59.6, "1:00"), (754, "12:34"), (3 * 3600 + 5, "3:00:05")])
def test_format_duration(seconds, text):
    assert format_duration(seconds) == text


# ------------------------------------------------------------------------------------------------ interrupts
class _Stop(KeyboardInterrupt):
    """What the test's SIGINT handler raises (a KeyboardInterrupt, as the CLI's SIGTERM/SIGHUP handler does)."""


@njit(nogil=True)
def _busy_kernel(started, n):
    """A kernel of ~0.1-0.3 s that returns arrays, as the geodesic loops do (numba converts each with a call
    into Python)."""
    started[0] = 1.0
    acc = 0.0
    for i in range(n):
        acc += np.sqrt(i + acc * 1e-12)
    return np.full(3, acc), np.zeros(2, np.int64), np.ones(1)


def _signal_during_a_kernel(call=lambda kernel: kernel()):
    """``call(kernel)`` in this (the main) thread, where ``kernel()`` runs the busy kernel; a helper thread sends
    SIGINT once the kernel has started (it waits on the kernel's own flag, not on a clock). Returns what the call
    raised (None if nothing)."""
    started = np.zeros(1)
    _busy_kernel(started, 10)  # compiled before the measured call
    started[0] = 0.0

    def send():
        while started[0] == 0.0:  # the kernel releases the GIL: this thread runs while it works
            pass
        os.kill(os.getpid(), signal.SIGINT)

    previous = signal.signal(signal.SIGINT, lambda *_: (_ for _ in ()).throw(_Stop()))
    helper = threading.Thread(target=send)
    try:
        helper.start()
        try:
            call(lambda: _busy_kernel(started, 30_000_000))
        except BaseException as exc:  # noqa: BLE001 - what numba raises is the point
            return exc
        finally:
            helper.join()
    finally:
        signal.signal(signal.SIGINT, previous)
    return None


def _guarded(kernel):
    with kernel_interrupts():
        return kernel()


def test_signal_during_a_numba_kernel_is_raised_as_the_interrupt():
    """A Ctrl-C that arrives while a compiled loop runs in the main thread is acted upon when numba boxes the
    result, and numba reports it as a SystemError caused by the KeyboardInterrupt; kernel_interrupts() raises
    the interrupt itself (so the CLI says "interrupted", exit 130, instead of a traceback and exit 1)."""
    raw = _signal_during_a_kernel()
    assert isinstance(interrupt_in(raw), _Stop), repr(raw)  # numba 0.6x: a SystemError caused by the _Stop
    assert isinstance(_signal_during_a_kernel(_guarded), _Stop)


def test_interrupt_in_finds_the_interrupt_in_a_chain_and_nothing_else():
    stop = _Stop()
    try:
        try:
            raise stop
        except _Stop as inner:
            raise SystemError("returned a result with an exception set") from inner
    except SystemError as exc:
        assert interrupt_in(exc) is stop
    assert interrupt_in(ValueError("x")) is None and interrupt_in(None) is None
    with pytest.raises(SystemError, match="genuine"):
        with kernel_interrupts():
            raise SystemError("genuine")


# ------------------------------------------------------------------------------------------------ paced kernel calls
def test_pacer_sizes_blocks_by_work_and_measured_speed():
    """Blocks of about BLOCK_SECONDS: from the conservative prior at first, then from the measured speed."""
    work = np.full(1000, 1000.0)  # 1000 expected pairs per source
    prior = NB.PRIOR_SECONDS_PER_PAIR  # what the geodesic queries start from
    pacer = Pacer(work, prior=prior, max_block=512)
    first = pacer.next(0)
    assert first == int(BLOCK_SECONDS / (1000 * prior))  # 5 sources at 40 us per pair
    pacer.record(0, first, first * 1000 * 2e-6)  # measured: 2 us per pair
    assert pacer.next(first) - first == 100  # 0.2 s / (1000 pairs x 2 us)
    assert Pacer(work, prior=prior, min_block=10).next(0) == 10  # e.g. arc: at least a source per thread
    assert Pacer(np.full(10, 1e12), prior=prior).next(0) == 1  # at least one source
    assert Pacer(np.ones(10), prior=prior, max_block=4).next(8) == 10  # never past the end
    # without a prior the first block is the smallest, and the measured speed sizes the next
    pacer = Pacer(work, min_block=3, max_block=512)
    assert pacer.next(0) == 3
    pacer.record(0, 3, 3 * 1000 * 2e-6)
    assert pacer.next(3) - 3 == 100


def test_interrupt_cancels_the_queued_blocks():
    """Ctrl-C while blocks run on the worker threads (here: raised by the progress callback after the first
    block): the queued blocks are dropped, so at most the blocks in flight (two per thread) run after it,
    not every block of the query (100 here)."""
    started = []
    pacer = Pacer(np.ones(100), seconds=np.inf, min_block=1, max_block=1)

    def interrupt(done, total):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_paced(lambda a, b: started.append(a), pacer, 100, n_threads=2, progress=interrupt)
    assert 1 <= len(started) <= 1 + 2 * 2, started


def test_interrupt_reported_by_numba_in_the_calling_thread_is_the_interrupt():
    stop = _Stop()

    def boxing_failed(a, b):  # what numba raises when a signal arrives during a kernel (see above)
        try:
            raise stop
        except _Stop as inner:
            raise SystemError("returned a result with an exception set") from inner

    with pytest.raises(_Stop):
        run_paced(boxing_failed, Pacer(np.ones(5)), 5, n_threads=1)


@pytest.mark.parametrize("method", ["window", "fmm", "arc"])
def test_blocks_never_change_a_neighbourhood(method):
    """Paced blocks (sized by time), one source per call and all in one call give bitwise the same result."""
    V, F = icosphere(30.0, 3)
    src = np.arange(0, len(V), 5)
    make = (lambda: ArcGeodesicNeighbourhoods(V, F, n_threads=2)) if method == "arc" else (
        lambda: GeodesicNeighbourhoods(V, F, method=method, n_threads=2))
    ref = make().query(None, None, None, src, None, 12.0, block_size=len(src))
    for bs in (None, 1):
        nb = make().query(None, None, None, src, None, 12.0, block_size=bs)
        for name in ("indptr", "vertex", "distance", "chord", "phi"):
            a, b = getattr(ref, name), getattr(nb, name)
            assert (a is None and b is None) or np.array_equal(a, b), (bs, name)


# ------------------------------------------------------------------------------------------------ bake and mc
@pytest.fixture
def small_sphere():
    V, F = icosphere(10.0, 2)
    return Mesh(V, F)


def test_bake_reports_its_sources_in_lines_when_stderr_is_not_a_terminal(small_sphere, capsys, monkeypatch):
    monkeypatch.setenv(P.INTERVAL_ENV, "0")  # a line at every update
    mat, light = material_from_options("skin1"), [parse_light_spec("directional:0,0,-1")]
    for transport, unit in (("direct", "sources"), ("hierarchical", "receivers")):
        quiet = bake(small_sphere, mat, light, BakeOptions(model="dipole", surface=SurfaceOptions(transport=transport)))
        assert capsys.readouterr().err == ""
        res = bake(small_sphere, mat, light, BakeOptions(
            model="dipole", progress="render", surface=SurfaceOptions(transport=transport)))
        lines = capsys.readouterr().err.splitlines()
        k = len(res.samples) if transport == "direct" else small_sphere.n_vertices
        assert lines and all(line.startswith("meshshade: render: ") for line in lines), lines
        assert lines[-1].startswith(f"meshshade: render: 100 % ({k}/{k} {unit})"), lines
        np.testing.assert_array_equal(res.radiance, quiet.radiance)


def test_mc_reports_photons_in_lines(small_sphere, capsys, monkeypatch):
    monkeypatch.setenv(P.INTERVAL_ENV, "0")
    mat = material_from_options("skin1")
    simulate(small_sphere, mat, [parse_light_spec("directional:0,0,-1")], MCOptions(
        photons=2000, beam_distances=False), progress=True)
    lines = capsys.readouterr().err.splitlines()
    assert lines and all(line.startswith("meshshade: mc: ") and "photons" in line for line in lines), lines


def test_interrupt_tells_the_running_kernels_to_stop():
    """The blocks already running when Ctrl-C comes are told to stop (``stop`` set to 1) and return at once,
    instead of finishing (one source of an exact window query can take a second). Here block 0 completes and
    triggers the interrupt; the other blocks wait for the stop signal (a guard ends them if it never comes)."""
    stop = np.zeros(1, np.int64)
    saw_stop = []

    def run(a, b):
        guard = time.monotonic() + 30.0  # only against a hang when the stop signal never comes
        while a > 0 and stop[0] == 0 and time.monotonic() < guard:
            time.sleep(0)  # yield to the other threads; the wait is on the flag
        saw_stop.append(bool(stop[0]))

    def interrupt(done, total):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_paced(run, Pacer(np.ones(10), seconds=np.inf, max_block=1), 10, n_threads=2, progress=interrupt,
                  stop=stop)
    assert saw_stop[0] is False and len(saw_stop) >= 2 and all(saw_stop[1:]), saw_stop


def test_window_kernel_returns_at_once_when_told_to_stop():
    """The exact-window kernel checks ``stop`` at every event: with it set, each source ends at its seed."""
    V, F = icosphere(30.0, 3)
    solver = GeodesicNeighbourhoods(V, F, n_threads=1)
    src = np.arange(0, len(V), 50)
    args = (src, np.full(src.size, -1), np.zeros((src.size, 3)), np.full(src.size, 48.0))
    full = solver._run_block(*args)[0]
    stopped = solver._run_block(*args, stop=np.ones(1, np.int64))[0]
    assert full.min() > 100 and stopped.max() <= 1, (full, stopped)


# ------------------------------------------------------------------------------------------------ polled interrupts
def test_polled_interrupts_raise_only_at_poll_and_restore_the_handlers():
    import os
    import signal as sig

    from meshshade.progress import polled_interrupts

    before = sig.getsignal(sig.SIGINT)
    with pytest.raises(KeyboardInterrupt):
        with polled_interrupts() as poll:
            os.kill(os.getpid(), sig.SIGINT)
            time.sleep(0.01)                 # the signal arrives: noted, nothing raised here
            reached = True
            poll()
            reached = False
    assert reached and sig.getsignal(sig.SIGINT) is before
    with pytest.raises(KeyboardInterrupt):   # one that arrives after the last poll is raised on leaving
        with polled_interrupts() as poll:
            poll()
            os.kill(os.getpid(), sig.SIGINT)
            time.sleep(0.01)
    with polled_interrupts() as poll:        # nothing noted: nothing raised
        poll()

    class Term(Exception):
        pass

    def raise_term(signum, frame):
        raise Term(signum)

    old = sig.signal(sig.SIGTERM, raise_term)   # the CLI's own SIGTERM handler is what poll() calls
    try:
        with pytest.raises(Term):
            with polled_interrupts() as poll:
                os.kill(os.getpid(), sig.SIGTERM)
                time.sleep(0.01)
                poll()
        assert sig.getsignal(sig.SIGTERM) is raise_term
    finally:
        sig.signal(sig.SIGTERM, old)


def test_polled_interrupts_outside_the_main_thread_do_nothing():
    import threading

    from meshshade.progress import polled_interrupts

    seen = []

    def body():
        with polled_interrupts() as poll:
            seen.append(poll())

    t = threading.Thread(target=body)
    t.start()
    t.join()
    assert seen == [None]


def test_run_in_blocks_covers_the_items_in_order_on_threads():
    seen = []
    out = run_in_blocks(lambda a, b: seen.append(threading.get_ident()) or (a, b), 1000, n_threads=2, block=64)
    assert out == [(a, min(a + 64, 1000)) for a in range(0, 1000, 64)]
    out = run_in_blocks(lambda a, b: (a, b), 5000, n_threads=4)   # default: 4 blocks per thread, >= 256 items
    assert [b - a for a, b in out] == [313] * 15 + [5000 - 15 * 313]
    assert run_in_blocks(lambda a, b: (a, b), 0) == []


def test_default_threads_follow_numba_in_the_calling_thread():
    import numba

    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        assert default_threads() == 1
    finally:
        numba.set_num_threads(before)
    assert 1 <= default_threads() <= (os.cpu_count() or 1)
