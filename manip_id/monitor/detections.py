"""A monitored log: residuals, flags against the bounds, and detections as time intervals.

A detection is a maximal run of consecutive samples where some joint has ``|r_j| > b_j``;
its ``start`` is the first such sample's time and ``stop`` the last one's [s, the log's
own time], ``joints`` the joints above their bound anywhere in it and ``peak`` the
largest ``|r_j|`` among those joints [N m or N].
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Detection:
    """One detection interval (module docstring).

    Attributes
    ----------
    start, stop: first and last flagged sample [s, the log's own time]
    joints: names of the joints above their bound in the interval
    peak: largest ``|r_j|`` of those joints in the interval [N m or N]
    peak_joint: the joint of the peak
    file: the log's label ("" for arrays)
    """

    start: float
    stop: float
    joints: list[str]
    peak: float
    peak_joint: str
    file: str = ""

    def to_dict(self) -> dict:
        """JSON-ready: ``file, start, stop, duration, joints, peak, peak_joint``."""
        return {
            "file": self.file,
            "start": float(self.start),
            "stop": float(self.stop),
            "duration": float(self.stop - self.start),
            "joints": list(self.joints),
            "peak": float(self.peak),
            "peak_joint": self.peak_joint,
        }


@dataclass(frozen=True)
class MonitorRun:
    """The observer over one log.

    Attributes
    ----------
    t: sample times, shape (N,) [s]
    residual: the residual ``r`` (estimated external torque), shape (N, nv) [N m or N]
    bounds: detection bounds per joint, shape (nv,) [N m or N] (inf: no detection)
    dof_names: joint names, length nv
    file: the log's label ("" for arrays)
    """

    t: np.ndarray
    residual: np.ndarray
    bounds: np.ndarray
    dof_names: list[str] = field(default_factory=list)
    file: str = ""

    @property
    def detected(self) -> np.ndarray:
        """``|r_j| > b_j`` per sample and joint, shape (N, nv)."""
        return np.abs(self.residual) > self.bounds

    @property
    def alarm_rate(self) -> float:
        """Fraction of samples where some joint is above its bound."""
        return float(self.detected.any(axis=1).mean())

    @property
    def alarm_rate_per_joint(self) -> np.ndarray:
        """Fraction of samples above the bound, per joint, shape (nv,)."""
        return self.detected.mean(axis=0)

    def detections(self) -> list[Detection]:
        """The detection intervals, in time order (module docstring)."""
        flags = self.detected
        anyf = flags.any(axis=1)
        if not anyf.any():
            return []
        edges = np.diff(np.concatenate([[0], anyf.astype(np.int8), [0]]))
        starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        out = []
        for a, b in zip(starts, stops, strict=True):
            joints = np.flatnonzero(flags[a:b].any(axis=0))
            mag = np.abs(self.residual[a:b][:, joints])
            k = int(np.argmax(mag.max(axis=0)))
            out.append(
                Detection(
                    start=float(self.t[a]),
                    stop=float(self.t[b - 1]),
                    joints=[self.dof_names[j] for j in joints],
                    peak=float(mag.max()),
                    peak_joint=self.dof_names[int(joints[k])],
                    file=self.file,
                )
            )
        return out

    def first_detection_after(self, time: float, joint: int | None = None) -> float | None:
        """Time of the first flagged sample at or after ``time`` [s] (of ``joint`` when
        given, else of any joint), or None."""
        flags = self.detected
        f = flags[:, joint] if joint is not None else flags.any(axis=1)
        idx = np.flatnonzero(f & (self.t >= time))
        return float(self.t[idx[0]]) if idx.size else None
