"""Command-line interface: a thin layer over the Python API (meshio pattern).

``main(argv=None) -> int``. Each subcommand has two modules: its one-line ``HELP`` and ``add_arguments`` in
``meshshade.cli.arguments.<cmd>`` (:data:`COMMANDS`; the options they share in
:mod:`meshshade.cli.arguments.common`), and what it does, ``run_<cmd>``, in ``meshshade.cli.<cmd>`` (the shared
options' meaning in :mod:`meshshade.cli.options`).

Start-up: this module imports only the first half, which imports neither numpy nor numba, so ``meshshade --help``,
``meshshade <cmd> --help`` and argument errors answer in about 0.1 s (``tools/benchmarks/bench_startup.py``).
:func:`main` installs its signal handling first, parses, and only then imports the command's module
(:func:`load_command`: numpy, numba, scipy, trimesh, about a second), so a Ctrl-C or SIGTERM at any moment from
the call of ``main`` on, that import included, ends the run as described below. (Before it, in the first
twentieth of a second while Python starts and imports this module, Python's own handling applies.)

What a user sees when something goes wrong, and the exit codes:

* a mistake (:class:`~meshshade.errors.MeshshadeError`, a malformed option, out of memory, standard output that
  cannot be written): one line ``meshshade: error: ...`` on stderr and exit code 2; warnings are one line each
  (``meshshade: warning: ...``);
* Ctrl-C (SIGINT), SIGTERM and SIGHUP: one line ``meshshade: interrupted ...`` and exit code 128 + the signal's
  number (130, 143, 129); one that lands after the outputs were committed (the process finishing: its threads,
  its interpreter shutting down) says so: ``meshshade: SIGTERM after the outputs were written (they are
  complete)``, same exit code (:func:`say_late_signals`, installed when ``main`` runs as the program);
* standard output closed by its reader (``meshshade profile ... | head -1``): silence and exit code 141, as a
  program killed by SIGPIPE.

Every command runs inside one :func:`meshshade.io.output_transaction`: its output files appear together when it
succeeds, and none of them (nor a folder it created) when it fails or is interrupted.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import logging
import os
import re
import signal
import sys
import threading
import warnings

from meshshade import __version__
from meshshade.cli.arguments import COMMANDS  # subcommand -> its arguments module (HELP, add_arguments)
from meshshade.errors import MeshshadeError

#: signals that stop a run like Ctrl-C does (temporary files removed, exit code 128 + number)
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


class Interrupted(KeyboardInterrupt):
    """Raised by the CLI's handler of SIGTERM and SIGHUP (a KeyboardInterrupt, so every clean-up that handles
    Ctrl-C handles them too)."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


class Parser(argparse.ArgumentParser):
    """argparse with a one-line error (``meshshade: error: bake: ...``) instead of the usage block."""

    def error(self, message):  # noqa: D401 - argparse's hook
        command = self.prog.split(" ", 1)[1] + ": " if " " in self.prog else ""
        self.exit(2, f"meshshade: error: {command}{message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="meshshade",
        description="Curvature-aware diffusion shading of translucent meshes (lengths in mm, coefficients 1/mm).")
    parser.add_argument("--verbose", "-v", action="store_true", help="log what is computed and chosen")
    parser.add_argument("--version", action="version", version="meshshade " + __version__)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, arguments in COMMANDS.items():
        sp = sub.add_parser(name, help=arguments.HELP, description=arguments.HELP)
        sp.add_argument("--quiet", "-q", action="store_true", help="no progress bars or notes")
        arguments.add_arguments(sp)
    return parser


def load_command(name: str):
    """``(run_<name>, meshshade.io)``: the function that runs ``meshshade <name>``, from ``meshshade.cli.<name>``,
    and the io package that holds the output transaction, imported now. They import numpy, numba, scipy and
    trimesh (about a second), so :func:`main` calls this once the arguments are parsed and its signal handling is
    in place. The package's only import of a module named at run time (tests/test_architecture.py, rule (f))."""
    io = importlib.import_module("meshshade.io")
    module = importlib.import_module(f"{__package__}.{name}")
    return getattr(module, f"run_{name}"), io


_NEGATIVE_VALUE = re.compile(r"^-(\d|\.\d|inf|nan)", re.IGNORECASE)


def join_negative_values(parser: argparse.ArgumentParser, argv: list[str]) -> list[str]:
    """``--azimuth -90,0,90`` -> ``--azimuth=-90,0,90`` for every option of the chosen subcommand that takes one
    value: argparse would take a value that starts with ``-`` and is not a single number for an option."""
    sub = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)
    name = next((a for a in argv if a in COMMANDS), None)
    if sub is None or name is None:
        return list(argv)
    takes_value = {opt for action in sub.choices[name]._actions if action.nargs is None and action.option_strings
                   for opt in action.option_strings}
    out, i = [], 0
    while i < len(argv):
        arg = argv[i]
        if arg in takes_value and i + 1 < len(argv) and _NEGATIVE_VALUE.match(argv[i + 1]):
            out.append(f"{arg}={argv[i + 1]}")
            i += 2
        else:
            out.append(arg)
            i += 1
    return out


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    print(f"meshshade: warning: {message}", file=sys.stderr)


def _raise_interrupted(signum, frame):
    raise Interrupted(signum)


def _late_signal(signum, frame):
    name = signal.Signals(signum).name
    try:
        sys.stderr.write(f"meshshade: {name} after the outputs were written (they are complete)\n")
        sys.stderr.flush()
    finally:
        os._exit(128 + signum)


def say_late_signals() -> None:
    """From now until the process ends, a stop signal (:data:`STOP_SIGNALS`) says that the outputs were already
    written and ends the process with 128 + its number (a command has finished: nothing is left to clean up).
    :func:`main` run as the program installs it as the command ends, with no moment between its own handlers and
    these."""
    if threading.current_thread() is threading.main_thread():
        for sig in STOP_SIGNALS:
            signal.signal(sig, _late_signal)


def _report_interrupted(exc) -> int:
    name = signal.Signals(exc.signum).name
    print(f"meshshade: interrupted by {name}; no partial output was left", file=sys.stderr)
    return 128 + exc.signum


def _interrupt_in_chain(exc):
    """The :class:`Interrupted` or KeyboardInterrupt behind ``exc`` (its causes and contexts), or None: a signal
    whose handler ran inside a C function that called back into Python (numba unpickling a cached kernel) comes
    out of that function as a SystemError caused by it."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, (Interrupted, KeyboardInterrupt)):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


@contextlib.contextmanager
def _stop_signals_interrupt(late: bool = False):
    """While a command is parsed, imported and run, SIGTERM and SIGHUP raise :class:`Interrupted` as Ctrl-C raises
    KeyboardInterrupt (only in the main thread, where Python delivers signals). At the end the previous handlers
    are restored, or with ``late`` those of :func:`say_late_signals` installed."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {}
    for sig in STOP_SIGNALS:
        if sig != signal.SIGINT:
            previous[sig] = signal.signal(sig, _raise_interrupted)
    try:
        yield
    finally:
        if late:
            say_late_signals()
        else:
            for sig, handler in previous.items():
                signal.signal(sig, handler)


class StdoutError(MeshshadeError):
    """Standard output cannot be written (a full device, an I/O error)."""


class _GuardedStdout:
    """``sys.stdout`` while a command runs: a failed write or flush becomes :class:`StdoutError` (one line, exit
    code 2); a closed pipe stays BrokenPipeError (quiet exit 141)."""

    def __init__(self, stream):
        self._stream = stream

    def _guard(self, method, *args):
        try:
            return method(*args)
        except BrokenPipeError:
            raise
        except OSError as exc:
            raise StdoutError(f"cannot write to standard output: {exc.strerror or exc}") from None

    def write(self, text):
        return self._guard(self._stream.write, text)

    def flush(self):
        return self._guard(self._stream.flush)

    def __getattr__(self, name):
        return getattr(self._stream, name)


@contextlib.contextmanager
def _guarded_stdout():
    original = sys.stdout
    sys.stdout = _GuardedStdout(original)
    try:
        yield
    finally:
        sys.stdout = original


def main(argv=None) -> int:
    """Run ``meshshade ARGV`` (``argv`` None: the program's own arguments, and then a signal after the command's
    outputs are written is reported as such: :func:`say_late_signals`); returns the exit code."""
    return _main(argv, late=argv is None)


def _main(argv, late: bool) -> int:
    # the signal handling first: a stop signal is one line and exit 128 + its number whether it lands while the
    # arguments are parsed, while the command's modules are imported (numba, scipy: a second) or while it runs
    with _stop_signals_interrupt(late=late):
        try:
            return _parse_and_run(argv)
        except Interrupted as exc:
            return _report_interrupted(exc)
        except (SystemError, ImportError) as exc:
            # a signal raised inside a C call back into Python (numba loading a kernel) or inside an import
            cause = _interrupt_in_chain(exc)
            if cause is None:
                raise
            if isinstance(cause, Interrupted):
                return _report_interrupted(cause)
            print("meshshade: interrupted; no partial output was left", file=sys.stderr)
            return 130
        except KeyboardInterrupt:
            print("meshshade: interrupted; no partial output was left", file=sys.stderr)
            return 130


def _parse_and_run(argv) -> int:
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        args = parser.parse_args(join_negative_values(parser, argv))
    except SystemExit as exc:  # --help, --version, or the one-line error of Parser.error: a code, not an exit
        return exc.code if isinstance(exc.code, int) else 2
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="meshshade: %(message)s")
    if args.command is None:
        parser.print_help()
        return 2
    with warnings.catch_warnings():
        warnings.showwarning = _one_line_warning
        io = None
        try:
            with _guarded_stdout():
                run, io = load_command(args.command)
                with io.output_transaction():
                    code = run(args)
                sys.stdout.flush()  # a full device or a closed pipe fails here, inside the handlers below
            return code
        except MeshshadeError as exc:
            if isinstance(exc, StdoutError) and io is not None:
                io.discard_stdout()
            print(f"meshshade: error: {exc}", file=sys.stderr)
            return 2
        except BrokenPipeError:  # the reader of stdout went away (| head): stop quietly, as `cat` would
            if io is not None:
                io.discard_stdout()
            return 141
        except MemoryError as exc:
            detail = str(exc).strip() or "the job needs more memory than the machine has"
            print(f"meshshade: error: out of memory: {detail}", file=sys.stderr)
            return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
