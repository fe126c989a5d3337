"""What C/C++ libraries write to file descriptor 2, captured and turned into one warning.

urdfdom (Pinocchio's URDF parser) and assimp (meshes) print to the process's
standard error directly, past Python's ``sys.stderr``; a non-XML URDF gives three
lines of C++ diagnostics above our own error message. :func:`native_stderr_captured`
redirects fd 2 to a temporary file around such a call: when the block succeeds, the
captured lines become one :class:`LibraryOutputWarning` (the command line prints it
as ``manip-id: warning: urdfdom: ...``); when it raises, they are dropped, since our
error message says what went wrong.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import threading
import warnings

_LOCK = threading.Lock()  # fd 2 is process-wide: one capture at a time


class LibraryOutputWarning(UserWarning):
    """Text a C/C++ library printed on standard error while manip_id called it."""


@contextlib.contextmanager
def native_stderr_captured(source: str = ""):
    """Capture fd-level stderr in the block (see the module docstring); re-entrant."""
    if not _LOCK.acquire(blocking=False):  # nested or concurrent: the outer one captures
        yield
        return
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
        lines = [" ".join(line.split()) for line in text.splitlines() if line.strip()]
        prefix = f"{source}: " if source else ""
        warnings.warn(prefix + "; ".join(dict.fromkeys(lines)), LibraryOutputWarning, stacklevel=3)
