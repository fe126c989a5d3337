"""Rows parsed once per run: a slow file's packed blocks recorded, then read back.

A command reads a log several times (the pre-fit audit, then the scan that checks
the rows and fixes the sampling grid). Text (CSV) and CDR messages (ROS 2 bags)
are slow to parse: a :class:`RowCache` records what a source yields the first time
a request ``chunks(chunk, start, stop)`` is made, the packed float64 blocks with
their boundaries, in a temporary binary file; the same request later is read back
from that file with plain reads, block for block. Every later pass
(:func:`~.stream.iter_rows`: windows, bad rows, their counts and messages) thus
sees exactly the blocks it would have parsed. A request that goes beyond what was
recorded (a first pass that stopped early, e.g. at the end of a time window)
parses the rest of it, recording it too. Other requests (other chunk sizes or row
ranges) are parsed.

The temporary files are removed by :meth:`RowCache.close` (also on ``with`` exit,
and by the CLI when a command is interrupted).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Generator, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._io import register_temporary, unregister_temporary

#: Formats whose rows are slow to parse (text, CDR messages): recorded by a cache.
SLOW_FORMATS = ("csv", "rosbag")


def is_slow(source) -> bool:
    """Whether ``source``'s rows are slow to parse (a format of :data:`SLOW_FORMATS`, or a
    compressed NPZ)."""
    return source.format in SLOW_FORMATS or bool(getattr(source, "compressed", False))


@dataclass
class _Recording:
    """The blocks of one request, in a binary file: their row counts, whether complete."""

    path: str
    blocks: list[int] = field(default_factory=list)
    complete: bool = False
    busy: bool = False  # a pass is recording it (a second one parses on its own)
    malformed: dict[int, str] = field(default_factory=dict)
    pending: Generator[np.ndarray, None, None] | None = None  # the wrapped pass, where it stopped
    parsed_malformed: dict[int, str] | None = None  # the malformed lines the wrapped pass found


class RowCache:
    """The rows of slow files, parsed once for one run (see the module docstring).

    Use as a context manager (or call :meth:`close`): the recordings are removed.
    ``n_parsed`` counts the blocks parsed and ``n_replayed`` those read back.
    """

    def __init__(self) -> None:
        self._recordings: dict[tuple, _Recording] = {}
        self.n_parsed = 0
        self.n_replayed = 0

    def wrap(self, key: tuple, source):
        """``source`` itself when it is fast to read, else a source recorded by this cache.

        ``key`` names what the source reads (file, its size and time, format options):
        sources of equal keys share their recordings.
        """
        return CachedSource(self, key, source) if is_slow(source) else source

    def recording(self, key: tuple) -> _Recording:
        rec = self._recordings.get(key)
        if rec is None:
            fd, path = tempfile.mkstemp(prefix="manip_id_parsed_", suffix=".f64")
            os.close(fd)
            register_temporary(path)
            rec = self._recordings[key] = _Recording(path)
        return rec

    def close(self) -> None:
        """Remove the recordings' files."""
        for rec in self._recordings.values():
            if rec.pending is not None:
                rec.pending.close()
            Path(rec.path).unlink(missing_ok=True)
            unregister_temporary(rec.path)
        self._recordings.clear()

    def __enter__(self) -> RowCache:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class CachedSource:
    """A source (see :mod:`~.stream`) whose requests a :class:`RowCache` records and replays.

    Same attributes as the wrapped source; ``malformed`` (CSV lines that could not be
    read, by row) holds those of the recorded rows too.
    """

    def __init__(self, cache: RowCache, key: tuple, inner):
        self.cache = cache
        self.key = key
        self.inner = inner
        self.path = inner.path
        self.format = inner.format
        self.layout = inner.layout
        self.joint_names = inner.joint_names
        self.n_rows = inner.n_rows
        self.compressed = bool(getattr(inner, "compressed", False))
        self.malformed: dict[int, str] = {}

    def chunks(self, chunk: int, start: int = 0, stop: int | None = None) -> Iterator[np.ndarray]:
        """Packed float64 rows ``start:stop``, in the blocks the wrapped source yields."""
        rec = self.cache.recording((self.key, int(chunk), int(start), stop))
        if rec.busy:  # another pass is recording this request: parse on our own
            yield from self.inner.chunks(chunk, start, stop)
            return
        width = self.layout.width
        self.malformed.update(rec.malformed)
        with open(rec.path, "rb") as fh:
            for k in list(rec.blocks):
                block = np.fromfile(fh, dtype="<f8", count=k * width)
                self.cache.n_replayed += 1
                yield block.reshape(k, width)
        if rec.complete:
            return
        rec.busy = True
        try:
            yield from self._record(rec, chunk, start, stop)
        finally:
            rec.busy = False

    def _record(self, rec: _Recording, chunk: int, start: int, stop):
        """The request's blocks after the recorded ones, from the wrapped source, recorded.

        The wrapped source's pass is kept when this one stops early, and resumed by the
        next pass that needs more (else a new pass of the wrapped source skips the
        recorded blocks)."""
        if rec.pending is None:
            rec.pending = self.inner.chunks(chunk, start, stop)
            rec.parsed_malformed = getattr(self.inner, "malformed", None)
            for _ in range(len(rec.blocks)):
                next(rec.pending)
        try:
            with open(rec.path, "ab") as fh:
                for block in rec.pending:
                    self.cache.n_parsed += 1
                    fh.write(np.ascontiguousarray(block, dtype="<f8").tobytes())
                    fh.flush()
                    rec.blocks.append(int(block.shape[0]))
                    if rec.parsed_malformed:
                        rec.malformed.update(rec.parsed_malformed)
                        self.malformed.update(rec.parsed_malformed)
                    yield block
        except GeneratorExit:  # this pass stopped early: the next one goes on from here
            raise
        except BaseException:  # the wrapped pass failed: a next one parses again
            rec.pending = None
            raise
        rec.complete, rec.pending = True, None


__all__ = ["SLOW_FORMATS", "CachedSource", "RowCache", "is_slow"]
