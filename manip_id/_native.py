"""What C/C++ libraries write to file descriptor 2, captured and turned into one warning.

urdfdom (Pinocchio's URDF parser) and assimp (meshes) print to the process's
standard error directly, past Python's ``sys.stderr``; a non-XML URDF gives three
lines of C++ diagnostics above our own error message. :func:`native_stderr_captured`
redirects fd 2 to a temporary file around such a call: when the block succeeds, the
captured lines become one :class:`LibraryOutputWarning` (the command line prints it
as ``manip-id: warning: urdfdom: ...``); when it raises, they are dropped, since our
error message says what went wrong.

Python libraries' log lines (Dask's ``distributed``, whose workers log every failed
task with its traceback) are silenced by :func:`library_logs_quiet`, in this process and
in the worker processes it starts: the failure reaches the client as the task's
exception, and the command line prints it as its one error line.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import sys
import tempfile
import threading
import warnings
from collections.abc import Callable

_LOCK = threading.RLock()  # fd 2 is process-wide: one thread at a time (nesting is fine)


class LibraryOutputWarning(UserWarning):
    """Text a C/C++ library printed on standard error while manip_id called it."""


#: Where a C++ library says where in its own sources it printed from: not for users.
_SOURCE_LOCATION = re.compile(r"\s*at line \d+ in \S+")


def _clean(text: str) -> list[str]:
    lines = [" ".join(_SOURCE_LOCATION.sub("", line).split()) for line in text.splitlines()]
    return list(dict.fromkeys(line for line in lines if line))


@contextlib.contextmanager
def native_stderr_captured(source: str = "", error: Callable[[str], Exception] | None = None):
    """Capture fd-level stderr in the block (see the module docstring); re-entrant.

    With ``error``, a block that succeeds although the library printed ``Error`` lines
    (urdfdom skips an unparsable inertial element and goes on: a body without mass)
    raises ``error(message)`` instead of warning.
    """
    _LOCK.acquire()
    try:
        try:
            sys.stderr.flush()
            saved = os.dup(2)
        except (OSError, ValueError, AttributeError):  # no real fd 2 (embedded use)
            yield
            return
        captured = tempfile.TemporaryFile()
        ok = False
        try:
            os.dup2(captured.fileno(), 2)
            try:
                yield
                ok = True
            finally:
                os.dup2(saved, 2)
        finally:
            os.close(saved)
            captured.seek(0)
            text = captured.read().decode("utf-8", "replace")
            captured.close()
    finally:
        _LOCK.release()
    if ok and text.strip():
        lines = _clean(text)
        prefix = f"{source}: " if source else ""
        errors = [line.removeprefix("Error:").strip() for line in lines if "Error" in line]
        if error is not None and errors:
            raise error(prefix + "; ".join(errors))
        warnings.warn(prefix + "; ".join(lines), LibraryOutputWarning, stacklevel=3)


#: The loggers of the Dask libraries and of the event loop under them.
QUIET_LOGGERS = ("distributed", "dask", "tornado", "bokeh", "asyncio")
#: The variable distributed's logging configuration reads when it is imported (also in
#: the worker processes, which inherit the environment).
DASK_LOG_VARIABLE = "DASK_LOGGING__DISTRIBUTED"


@contextlib.contextmanager
def library_logs_quiet():
    """Silence the :data:`QUIET_LOGGERS` in the block (see the module docstring).

    The environment and the loggers' levels are given back afterwards.
    """
    saved_env = os.environ.get(DASK_LOG_VARIABLE)
    os.environ[DASK_LOG_VARIABLE] = "critical"
    loggers = [logging.getLogger(name) for name in QUIET_LOGGERS]
    levels = [logger.level for logger in loggers]
    for logger in loggers:
        logger.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for logger, level in zip(loggers, levels, strict=True):
            logger.setLevel(level)
        if saved_env is None:
            os.environ.pop(DASK_LOG_VARIABLE, None)
        else:
            os.environ[DASK_LOG_VARIABLE] = saved_env
