"""The audit's results: per joint, per file, per run; their table and JSON."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..datasets import FileSpec, Window
from ..datasets.stream import READ_CHUNK
from ..errors import DataError, InputError


@dataclass(frozen=True)
class AuditOptions:
    """How the audit reads the files (the same options as the fit's).

    Attributes
    ----------
    torque_scale: one gain or one per joint, ``tau_j <- G_j tau_j``; None: 1.
    drop_bad_rows: drop (and count) bad rows instead of refusing the file.
    standstill: velocity below which a joint is at rest [rad/s or m/s]; None:
        :data:`~manip_id.datasets.quality.STANDSTILL`.
    cutoff: low-pass cut-off [Hz] for files without ddq; None: the default.
    max_delay: largest delay searched [s].
    read_chunk: rows per block read from a file.
    currents: the torque columns hold currents on purpose (drive-gain runs): scales are
        reported, not suggested as a torque scale.
    """

    torque_scale: float | tuple[float, ...] | None = None
    drop_bad_rows: bool = False
    standstill: float | None = None
    cutoff: float | None = None
    max_delay: float = 0.1
    read_chunk: int = READ_CHUNK
    currents: bool = False

    def __post_init__(self):
        ts = self.torque_scale
        if ts is not None and not np.isscalar(ts):
            object.__setattr__(self, "torque_scale", tuple(float(g) for g in np.ravel(ts)))
        if self.standstill is not None and not self.standstill > 0:
            raise InputError(f"the standstill threshold must be positive, got {self.standstill}")
        if not (math.isfinite(self.max_delay) and self.max_delay >= 0):
            raise InputError(f"max_delay must be >= 0 seconds, got {self.max_delay}")


@dataclass(frozen=True)
class JointAudit:
    """One joint of one file: ``scale`` (measured / nominal torque), ``delay`` [s] of the
    torque stream (the file's), ``offset`` [N m or N], ``standstill`` (share of rows at
    rest), ``explained`` (share of the residual variance the nominal column explains),
    ``own_delay`` [s] (the lag that best fits this joint's torque alone: unmodelled
    friction dynamics show there, so it is reported, not acted upon). None: not
    determined by this file."""

    joint: str
    scale: float | None
    delay: float | None
    offset: float | None
    standstill: float
    explained: float | None = None
    own_delay: float | None = None

    def to_dict(self) -> dict:
        return {
            "joint": self.joint,
            "scale": num(self.scale),
            "delay": num(self.delay),
            "offset": num(self.offset),
            "standstill": num(self.standstill),
            "explained": num(self.explained),
            "own_delay": num(self.own_delay),
        }


@dataclass
class FileAudit:
    """The audit of one file: its joints, its findings (sentences) and what to pass.

    ``suggestions`` holds the options the findings recommend: ``torque_scale`` (one
    per joint; None for a joint whose scale these data do not determine), ``delay`` [s]
    (one per joint), ``trim_standstill`` (bool). ``kept``:
    the window ``--trim-standstill`` keeps (None: nothing to trim). ``delay_gain``: the
    share of the held-out torque error the file's delay removes against no delay (a
    delay is reported as a finding only when it removes at least :data:`DELAY_GAIN`).
    """

    spec: FileSpec
    n_rows: int
    rate: float
    static: bool
    joints: list[JointAudit]
    findings: list[str] = field(default_factory=list)
    rest: tuple[float, float] = (0.0, 0.0)
    kept: Window | None = None
    dropped: dict[str, int] = field(default_factory=dict)
    suggestions: dict = field(default_factory=dict)
    delay_gain: float | None = None

    @property
    def file(self) -> str:
        return self.spec.label

    def to_dict(self) -> dict:
        return {
            "file": self.file,
            "n_rows": self.n_rows,
            "rate": num(self.rate),
            "static": self.static,
            "findings": list(self.findings),
            "joints": [j.to_dict() for j in self.joints],
            "delay_gain": num(self.delay_gain),
            "rest": {"start": num(self.rest[0]), "end": num(self.rest[1])},
            "kept_window": None if self.kept is None else str(self.kept),
            "dropped": dict(self.dropped),
            "suggestions": dict(self.suggestions),
        }


@dataclass
class Audit:
    """The audit of a run's files (see the module docstring)."""

    robot: str
    files: list[FileAudit]
    #: the files that could not be audited: label -> why (the others are audited all the same)
    failed: dict[str, str] = field(default_factory=dict)

    @property
    def findings(self) -> list[str]:
        """Every finding, prefixed with its file."""
        return [f"{fa.file}: {f}" for fa in self.files for f in fa.findings]

    def to_dict(self) -> dict:
        out: dict = {"robot": self.robot, "files": [fa.to_dict() for fa in self.files]}
        if self.failed:
            out["failed"] = dict(self.failed)
        return out

    def check(self) -> None:
        """Raise one :class:`DataError` naming every file that could not be audited."""
        if self.failed:
            n = len(self.failed) + len(self.files)
            raise DataError(
                f"{len(self.failed)} of {n} file(s) cannot be read: "
                + "; ".join(self.failed.values())
            )

    def trimmed(self) -> list[FileSpec]:
        """The files with the windows ``--trim-standstill`` keeps (others as they were)."""
        return [fa.spec if fa.kept is None else fa.spec.with_window(fa.kept) for fa in self.files]

    def text(self, *, verbose: bool = False) -> str:
        """The audit as printed before a fit: its findings (one line when it found
        nothing); with ``verbose`` the full :meth:`table` (every file and joint)."""
        if verbose:
            return self.table()
        found = self.findings
        head = f"pre-fit audit against the nominal model of {self.robot}"
        if not found:
            return f"{head}: nothing found in {len(self.files)} file(s)"
        return "\n".join([f"{head}: {len(found)} finding(s)"] + [f"  - {f}" for f in found])

    def table(self) -> str:
        """One compact table: a row per file and joint, then the findings."""
        head = (
            f"{'file':<28} {'rows':>8} {'rate [Hz]':>9}  {'joint':<22} {'scale':>7} "
            f"{'delay [ms]':>10} {'offset [N m]':>12} {'rest':>5}"
        )
        lines = [f"audit against the nominal model of {self.robot}", head]
        for fa in self.files:
            name = fa.file if len(fa.file) <= 28 else "..." + fa.file[-25:]
            for k, j in enumerate(fa.joints):
                left = f"{name:<28} {fa.n_rows:>8} {fa.rate:>9.4g}" if k == 0 else " " * 47
                lines.append(
                    f"{left}  {j.joint[-22:]:<22} {fmt(j.scale, '+.3f'):>7} "
                    f"{fmt(None if j.delay is None else 1e3 * j.delay, '+.2f'):>10} "
                    f"{fmt(j.offset, '+.3g'):>12} {100 * j.standstill:>4.0f}%"
                )
            if fa.delay_gain is not None and fa.joints and fa.joints[0].delay is not None:
                lines.append(
                    f"  (the delay {1e3 * fa.joints[0].delay:+.3g} ms removes "
                    f"{100 * fa.delay_gain:.2g} % of the held-out torque error)"
                )
            lines += [f"  - {f}" for f in fa.findings] or ["  - no finding"]
        for label, why in self.failed.items():
            lines += [f"{label}: not audited", f"  - {why}"]
        return "\n".join(lines)


def num(x) -> float | None:
    return None if x is None or not math.isfinite(float(x)) else float(x)


def fmt(x, spec: str) -> str:
    return "n/d" if x is None else format(x, spec)


# ---------------------------------------------------------------- reading
