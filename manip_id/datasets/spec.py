"""File specifications: a path, an optional window, and how to read it.

On the command line a file may carry a window after an ``@``::

    run1.csv@12.5:40     seconds 12.5 <= t - t_0 < 40 of the file's own time
    run1.csv@:40         from the start to 40 s;  run1.csv@12.5:  from 12.5 s to the end
    run1.csv@#1000:5000  samples 1000 <= k < 5000 (0-based row indices of the file)

``t_0`` is the file's first time stamp, so a window reads the same on a log
stamped from 0 and on a ROS bag stamped in seconds since 1970. Both bounds are
half-open, like Python slices. A path that exists as written is never split at
an ``@``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..robot.transmission import Transmission, load_transmission
from .adjust import check_time_unit

_NUM = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_TIME = re.compile(rf"^\s*({_NUM})?\s*:\s*({_NUM})?\s*$")
_INDEX = re.compile(r"^\s*(?:#(\d+))?\s*:\s*#?(\d+)?\s*$")


@dataclass(frozen=True)
class Window:
    """A part of one file: seconds from its first stamp (``unit="s"``) or row indices.

    ``start`` (inclusive) and ``stop`` (exclusive); None is the file's start / end.
    """

    start: float | None = None
    stop: float | None = None
    unit: str = "s"

    def __post_init__(self):
        if self.unit not in ("s", "index"):
            raise InputError(f"window unit must be 's' or 'index', got {self.unit!r}")
        for name in ("start", "stop"):
            v = getattr(self, name)
            if v is None:
                continue
            if not math.isfinite(v) or v < 0:
                raise InputError(f"window {name} must be a finite value >= 0, got {v}")
            if self.unit == "index":
                if int(v) != v:
                    raise InputError(f"sample-index window {name} must be an integer, got {v}")
                object.__setattr__(self, name, int(v))
        if self.start is not None and self.stop is not None and self.stop <= self.start:
            raise InputError(f"the window {self} is empty: its stop is not after its start")

    def __str__(self) -> str:
        def fmt(v):
            if v is None:
                return ""
            return f"#{v}" if self.unit == "index" else f"{v:g}"

        return f"{fmt(self.start)}:{fmt(self.stop)}"

    @classmethod
    def parse(cls, text: str, what: str = "window") -> Window:
        """``"START:STOP"`` [s] or ``"#A:#B"`` (sample indices); either bound may be empty."""
        text = str(text)
        m = _INDEX.match(text)
        if m and "#" in text:
            a, b = m.groups()
            return cls(None if a is None else int(a), None if b is None else int(b), "index")
        m = _TIME.match(text)
        if m:
            a, b = m.groups()
            return cls(None if a is None else float(a), None if b is None else float(b), "s")
        raise InputError(
            f"{what} {text!r}: expected START:STOP in seconds (e.g. 2.5:30, :30, 2.5:) "
            "or #A:#B in sample indices (e.g. #1000:#5000)"
        )


@dataclass(frozen=True)
class FileSpec:
    """One data file (or bag folder) and how to read it.

    Attributes
    ----------
    path: the file or folder.
    window: part of the file, or None for all of it.
    format: "npz", "csv", "panda_gaz2019", "rosbag"; default from the path.
    columns: CSV column map (see :func:`~manip_id.datasets.load_dataset`).
    topic: ROS bag topic of ``sensor_msgs/msg/JointState``; default the only one.
    time_unit: unit of the stamps, "s", "ms", "us" or "ns" (None: seconds); see
        :mod:`~.adjust`.
    delay: lag [s] of the torque stream behind the motion stream, one value or one per
        joint; the rows pair the motion of ``t`` with the torque of ``t + delay``.
    rate: sampling rate [Hz] of a file without a time column (``t_k = k / rate``); a
        file with one keeps its stamps.
    transmission: the drive train (:class:`~manip_id.robot.transmission.Transmission`); with
        ``signals = "motor"`` the file's positions, velocities, accelerations and torques
        are motor-side and are converted to the joint side as they are read.
    """

    path: Path
    window: Window | None = None
    format: str | None = None
    columns: Mapping | None = field(default=None, compare=False)
    topic: str | None = None
    time_unit: str | None = None
    delay: float | tuple[float, ...] | None = None
    rate: float | None = None
    transmission: Transmission | None = field(default=None, compare=False)

    def __post_init__(self):
        if self.rate is not None:
            rate = float(self.rate)
            if not (math.isfinite(rate) and rate > 0):
                raise InputError(f"the sampling rate must be a positive number [Hz], got {rate}")
            object.__setattr__(self, "rate", rate)
        object.__setattr__(self, "transmission", load_transmission(self.transmission))
        object.__setattr__(self, "path", Path(self.path).expanduser())
        object.__setattr__(self, "time_unit", check_time_unit(self.time_unit))
        d = self.delay
        if d is not None:
            values = tuple(float(x) for x in np.ravel(np.asarray(d, dtype=float)))
            if not values or not all(math.isfinite(x) for x in values):
                raise InputError(f"a delay must be finite seconds, got {d!r}")
            object.__setattr__(self, "delay", values[0] if len(values) == 1 else values)
        if self.window is not None and not isinstance(self.window, Window):
            object.__setattr__(self, "window", Window.parse(self.window))

    @property
    def label(self) -> str:
        """The spec as written on the command line: ``path[@window]``."""
        return str(self.path) + (f"@{self.window}" if self.window is not None else "")

    def with_window(self, window: Window | None) -> FileSpec:
        """The same file with another window."""
        return replace(self, window=window)


def parse_file_spec(text, *, window=None, **kwargs) -> FileSpec:
    """A :class:`FileSpec` from ``"PATH"``, ``"PATH@START:STOP"`` or ``"PATH@#A:#B"``.

    ``window`` (a :class:`Window` or its text) applies when the text has none;
    other keywords go to :class:`FileSpec`. A FileSpec passes through (taking
    ``window`` if it has none).
    """
    if isinstance(text, FileSpec):
        if text.window is None and window is not None:
            return text.with_window(window if isinstance(window, Window) else Window.parse(window))
        return text
    text = str(text)
    path, own = text, None
    if "@" in text and not Path(text).expanduser().exists():
        head, _, tail = text.rpartition("@")
        if head:
            path, own = head, Window.parse(tail, what=f"window of {head}")
    if own is None and window is not None:
        own = window if isinstance(window, Window) else Window.parse(window, what="--window")
    return FileSpec(Path(path), own, **kwargs)
