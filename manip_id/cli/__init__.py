"""The ``manip-id`` command, and its one exception boundary.

Each module of this package that defines ``register(subparsers)`` adds one
subcommand; ``register`` creates its parser and sets ``func`` to a callable
``func(args) -> int | None``. ``args.outputs`` is the command's
:class:`~manip_id._io.OutputSet`: outputs are reserved there before the work and
published together at the end.

:func:`main` is the only place that turns exceptions into exit statuses:

=============================================  ======  ==============================
what happened                                  status  stderr
=============================================  ======  ==============================
bad input (:class:`~manip_id.errors.ManipIdError`,  2   ``manip-id: error: ...`` (one line)
or a bad option)
Ctrl-C (SIGINT)                                130     ``manip-id: interrupted``
SIGTERM / SIGHUP                               143/129 ``manip-id: terminated``
anything else: a bug                           1       ``manip-id: internal error (a bug)
                                                       ...; rerun with --debug``
=============================================  ======  ==============================

Whatever happens, unpublished temporaries are removed and the child processes this
command started are stopped. A SIGTERM whose exception Python swallows (raised inside a
weakref callback or a ``__del__``, as while a Dask cluster closes) is still the end of the
run: no "Exception ignored" traceback, nothing published, status 143 (``_received``).
Warnings (NumPy, SciPy, ours) are printed once each as ``manip-id: warning: ...``;
tracebacks appear only with ``--debug``.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import pkgutil
import re
import signal
import sys
import traceback
import warnings

#: BLAS threads of the command, unless the environment sets them (read when NumPy loads,
#: so set before the first import of it): one. The command's matrices are small (a few
#: hundred parameters at most), its parallel work runs in processes (``--workers``), and
#: threaded BLAS on such matrices, on a busy machine, made the log-Cholesky solve of the
#: Panda log 90x slower (60 iterations: 14.7 s against 0.16 s; see CHANGELOG).
BLAS_THREADS = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
for _name, _value in BLAS_THREADS.items():
    os.environ.setdefault(_name, _value)

import psutil  # noqa: E402 (after the BLAS threads are set)

from .._io import OutputSet, remove_temporaries  # noqa: E402
from .._native import (  # noqa: E402 (native_stderr_captured: re-exported, as earlier)
    library_logs_quiet,
    native_stderr_captured,  # noqa: F401
)
from ..errors import ManipIdError, did_you_mean  # noqa: E402
from ._common import warn  # noqa: F401, E402 (the commands' warnings, as earlier releases)

PROG = "manip-id"


class Terminated(BaseException):
    """Raised in the main thread by the SIGTERM / SIGHUP handler of :func:`main`."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


class OneLineParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line (``manip-id CMD: error: ...``), exit 2,
    with "did you mean" for a misspelt option, command or choice."""

    def parse_args(self, args=None, namespace=None):
        namespace, extras = self.parse_known_args(args, namespace)
        if extras:
            options = self._options_of(namespace)
            hints = "".join(
                did_you_mean(x.split("=", 1)[0], options) for x in extras if x[:1] == "-"
            )
            self.error(f"unrecognized arguments: {' '.join(extras)}{hints}")
        return namespace

    def _options_of(self, namespace) -> list[str]:
        """The option strings of this parser and of the command ``namespace`` chose."""
        options = [o for a in self._actions for o in a.option_strings]
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                command = action.choices.get(getattr(namespace, action.dest, None) or "")
                if command is not None:
                    options += [o for a in command._actions for o in a.option_strings]
        return [o for o in options if o.startswith("--")]

    def error(self, message: str):
        bad = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if bad:
            message += did_you_mean(bad.group(1), re.findall(r"'([^']*)'", bad.group(2)))
        self.exit(2, f"{self.prog}: error: {_one_line(message)} (see {self.prog} --help)\n")


#: The longest message line printed [characters]; longer ones are cut (a safety net: the
#: messages themselves quote user values cut to :data:`~manip_id.errors.QUOTE_LIMIT`).
MAX_LINE = 4000


def _one_line(text: str) -> str:
    parts = [line.strip() for line in str(text).splitlines() if line.strip()]
    line = "; ".join(parts) if parts else ""
    if len(line) > MAX_LINE:
        head, tail = line[: MAX_LINE // 2], line[-MAX_LINE // 4 :]
        line = f"{head} ... {tail} (message cut: {len(line)} characters)"
    return line


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand found in this package."""
    parser = OneLineParser(
        prog=PROG,
        description="Identify the dynamic parameters of robot manipulators.",
    )
    parser.add_argument(
        "--debug",
        action="store_true",
        help="show the traceback of an internal error (also accepted after the command)",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=OneLineParser)
    sub.required = True
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        register = getattr(module, "register", None)
        if register is not None:
            register(sub)
    for command in sub.choices.values():
        command.add_argument(
            "--debug", action="store_true", default=argparse.SUPPRESS, help=argparse.SUPPRESS
        )
    return parser


# ------------------------------------------------------------------ warnings
class _WarningPrinter:
    """``warnings.showwarning`` replacement: ``manip-id: warning: ...`` once per message."""

    def __init__(self):
        self.seen: set[str] = set()

    def __call__(self, message, category, filename, lineno, file=None, line=None):
        text = _one_line(str(message))
        module = (category.__module__ or "").split(".")[0]
        origin = ""
        if not filename or "manip_id" not in str(filename).replace(os.sep, "/"):
            origin = _library(str(filename)) or module
            origin = "" if origin in ("builtins", "manip_id", "") else f"{origin}: "
        line_out = f"{PROG}: warning: {origin}{text}"
        if line_out in self.seen:
            return
        self.seen.add(line_out)
        print(line_out, file=sys.stderr)


def _library(filename: str) -> str:
    """The top-level package a source file belongs to (``numpy``, ``scipy``), if any."""
    parts = filename.replace(os.sep, "/").split("/")
    if "site-packages" in parts:
        i = parts.index("site-packages")
        if i + 1 < len(parts):
            return parts[i + 1].removesuffix(".py")
    return ""


# ---------------------------------------------------------- child processes
def stop_children(timeout: float = 3.0) -> None:
    """Terminate (then kill) every process this process started, recursively."""
    try:
        children = psutil.Process().children(recursive=True)
    except psutil.Error:  # pragma: no cover
        return
    for child in children:
        try:
            child.terminate()
        except psutil.Error:
            pass
    _, alive = psutil.wait_procs(children, timeout=timeout)
    for child in alive:
        try:
            child.kill()
        except psutil.Error:
            pass


# ----------------------------------------------------------------- the main
#: The termination signal received by :func:`main` (None: none). Python swallows an
#: exception raised inside a weakref callback or a ``__del__`` (it prints "Exception
#: ignored in ..." with a traceback and goes on): a SIGTERM landing there, as it can while
#: a Dask cluster closes, would be lost. So the handler also records it here; the
#: swallowed :class:`Terminated` is not printed (:func:`_unraisable`), the outputs are not
#: published (:attr:`OutputSet.before_publish`) and :func:`main` ends as terminated.
_received: list[int] = []


def _check_terminated() -> None:
    """Raise :class:`Terminated` when a termination signal was received (and swallowed)."""
    if _received:
        raise Terminated(_received[0])


def _unraisable(default):
    """A ``sys.unraisablehook`` that keeps quiet about a swallowed :class:`Terminated`."""

    def hook(unraisable):
        if unraisable.exc_type is not None and issubclass(unraisable.exc_type, Terminated):
            return  # recorded in _received: main() ends as terminated
        default(unraisable)

    return hook


def _install_signal_handlers():
    """SIGTERM and SIGHUP raise :class:`Terminated` in the main process (not in forks)."""
    if not hasattr(signal, "SIGTERM"):  # pragma: no cover
        return {}
    main_pid = os.getpid()

    def handler(signum, frame):
        if os.getpid() != main_pid:  # a forked worker: leave the parent's state alone
            os._exit(128 + signum)
        if not _received:
            _received.append(signum)
        raise Terminated(signum)

    old = {}
    for name in ("SIGTERM", "SIGHUP"):
        sig = getattr(signal, name, None)
        if sig is None:
            continue
        try:
            old[sig] = signal.signal(sig, handler)
        except ValueError:  # not the main thread (main() called from a thread)
            break
    return old


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit status (see the module docstring)."""

    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv[: argv.index("--")] if "--" in argv else "--debug" in argv
    _received.clear()
    old_handlers = _install_signal_handlers()
    old_hook = sys.unraisablehook
    sys.unraisablehook = _unraisable(old_hook)
    OutputSet.before_publish = _check_terminated
    outputs = OutputSet()
    status = 0
    interrupted = False
    quiet = contextlib.nullcontext() if debug else library_logs_quiet()  # Dask's log lines
    with quiet, warnings.catch_warnings():
        warnings.simplefilter("default")
        warnings.filterwarnings("ignore", category=DeprecationWarning)
        warnings.filterwarnings("ignore", category=PendingDeprecationWarning)
        warnings.filterwarnings("ignore", category=ResourceWarning)  # libraries' leaks
        if not debug:  # multiprocessing's note when a worker cluster's resource tracker
            # was stopped with it: the library's bookkeeping, nothing the user acts on
            warnings.filterwarnings("ignore", message="resource_tracker: process died")
        warnings.showwarning = _WarningPrinter()
        try:
            parser = build_parser()
            args = parser.parse_args(argv)
            args.outputs = outputs
            status = int(args.func(args) or 0)
            _check_terminated()  # a signal whose exception was swallowed on the way
        except ManipIdError as exc:
            if debug:
                traceback.print_exc()
            print(f"{PROG}: error: {_one_line(str(exc))}", file=sys.stderr)
            status = 2
        except KeyboardInterrupt:
            print(f"\n{PROG}: interrupted", file=sys.stderr)
            status, interrupted = 130, True
        except Terminated as exc:
            print(f"{PROG}: terminated", file=sys.stderr)
            status, interrupted = 128 + exc.signum, True
        except SystemExit as exc:  # argparse (--help, bad options)
            code = exc.code
            status = code if isinstance(code, int) else (0 if code is None else 2)
        except BrokenPipeError:  # stdout closed early (`manip-id rank panda | head`)
            try:
                sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - no flush error at exit
            except OSError:  # pragma: no cover
                pass
            status = 1
        except MemoryError:
            if debug:
                traceback.print_exc()
            print(
                f"{PROG}: error: out of memory (this is a bug: manip-id should have refused "
                "the job up front; rerun with --debug for the traceback)",
                file=sys.stderr,
            )
            status = 1
        except Exception as exc:
            if debug:
                traceback.print_exc()
            print(
                f"{PROG}: internal error (a bug): {type(exc).__name__}: {_one_line(str(exc))}; "
                "rerun with --debug for the traceback",
                file=sys.stderr,
            )
            status = 1
        finally:
            for sig in old_handlers:  # a second signal must not interrupt the cleanup
                signal.signal(sig, signal.SIG_IGN)
            outputs.discard()
            remove_temporaries()
            if interrupted:
                stop_children()
            for sig, old in old_handlers.items():
                signal.signal(sig, old)
            sys.unraisablehook = old_hook
            OutputSet.before_publish = None
    return status


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
