"""The data-quality summary of one file, accumulated block by block before the fit.

For the rows a fit would see (after the window, bad rows and the torque scale):

- time: duration [s], mean rate [Hz], jitter (std of the step over its mean),
  gaps (steps longer than ``GAP_FACTOR`` times the median step, from a
  histogram of log10 steps) and the largest step;
- rows with NaN/Inf dropped (with ``drop_bad_rows``) and the first of them;
- positions against the joint limits: a warning per joint outside them, with
  how far, and a hint when the values look like degrees;
- velocity consistency per joint, over windows of about ``VELOCITY_WINDOW``
  seconds (m samples): ``||Delta q - Delta I|| / ||Delta I||`` with ``Delta q =
  q_{k+m} - q_k`` and ``Delta I`` the trapezoid integral of dq over the same
  samples (``q(t) = int dq dt``; over a window, sensor noise in q enters only
  at its two ends and noise in dq averages out, so the figure reflects units,
  lags or swapped columns rather than noise), and the sign of their correlation.
  Quantization-aware: the encoder's resolution ``r_j`` is estimated as the smallest
  non-zero step of ``q_j``, and only windows whose motion ``max(|Delta q|, |Delta I|)``
  exceeds ``MOTION_STEPS r_j`` count (a histogram of the windows' motion per joint, so
  the threshold applies after the pass). A *static* file (every joint's span of q
  within ``max(STATIC_STEPS r_j, STATIC_SPAN)``) gets no velocity warnings: its motion
  of q is quantization noise;
- standstill share per joint: samples with ``|dq_j| < eps``;
- torque saturation per joint: share of samples at ``>= 99 %`` of the effort
  limit, and share sitting exactly at the largest ``|tau_j|`` (a clipped signal).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .layout import Layout

#: A step longer than this many median steps is a gap.
GAP_FACTOR = 2.0
#: Default standstill threshold [rad/s] when no velocity deadband is given.
STANDSTILL = 1e-2
#: Relative velocity mismatch above which a warning is issued.
VELOCITY_MISMATCH = 0.2
#: Length [s] of the windows over which q increments are compared with the integral of dq.
VELOCITY_WINDOW = 0.02
#: Share of samples at the largest ``|tau|`` above which a joint looks clipped.
CLIPPED_SHARE = 1e-3
_BINS = np.linspace(-9.0, 3.0, 2401)  # log10 of the step [s], 0.005-decade bins
#: A velocity window counts when its motion exceeds this many encoder steps.
MOTION_STEPS = 10.0
#: A file is static when no joint's q spans more than this many encoder steps ...
STATIC_STEPS = 10.0
#: ... or, for finer (or unquantized) positions, more than this [rad or m].
STATIC_SPAN = 1e-3
_MOTION_BINS = 4 * 20  # windows' motion: quarter decades from 1e-15 to 1e5


def encoder_resolution(q) -> np.ndarray:
    """Per column, the smallest non-zero step ``|q_{k+1} - q_k|`` [rad or m]; inf when q
    never changes. Shape (nq,) from q of shape (N, nq)."""
    q = np.asarray(q, dtype=float)
    out = np.full(q.shape[1], np.inf)
    for a in range(0, q.shape[0] - 1, _STEP_BLOCK):  # blocks: no (N, nq) temporaries
        steps = np.abs(np.diff(q[a : a + _STEP_BLOCK + 1], axis=0))
        steps[steps == 0] = np.inf
        out = np.minimum(out, steps.min(axis=0))
    return out


_STEP_BLOCK = 65536  # rows per block of encoder_resolution


def static_span(resolution) -> np.ndarray:
    """The span of q [rad or m] within which a joint counts as still, per column:
    ``max(STATIC_STEPS r_j, STATIC_SPAN)`` for the encoder resolution ``r_j``."""
    res = np.asarray(resolution, dtype=float)
    return np.maximum(STATIC_STEPS * np.where(np.isfinite(res), res, 0.0), STATIC_SPAN)


@dataclass
class DataQuality:
    """Data-quality summary of one file (see the module docstring); ``to_dict`` is its JSON."""

    file: str
    format: str
    window: str | None
    joints: list[str]
    n_samples: int = 0
    n_dropped: int = 0
    first_dropped: int | None = None
    t_start: float = math.nan
    t_end: float = math.nan
    rate: float = math.nan
    jitter: float = math.nan
    dt_min: float = math.nan
    dt_max: float = math.nan
    n_gaps: int = 0
    q_min: list[float] = field(default_factory=list)
    q_max: list[float] = field(default_factory=list)
    velocity_mismatch: list[float] = field(default_factory=list)
    standstill_eps: float = STANDSTILL
    standstill_share: list[float] = field(default_factory=list)
    tau_max: list[float] = field(default_factory=list)
    saturated_share: list[float] | None = None
    clipped_share: list[float] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    #: rows dropped per reason ("non-finite", "implausible", "malformed line")
    dropped: dict[str, int] = field(default_factory=dict)
    #: encoder resolution per joint: smallest non-zero step of q (None: q never moved)
    resolution: list[float] = field(default_factory=list)
    #: no joint moved beyond the encoder's noise: velocity checks skipped
    static: bool = False

    @property
    def duration(self) -> float:
        """t_end - t_start [s]."""
        return self.t_end - self.t_start

    def to_dict(self) -> dict:
        def f(x):
            return None if x is None or not math.isfinite(x) else float(x)

        def per(values):
            return None if values is None else dict(zip(self.joints, map(f, values), strict=False))

        return {
            "file": self.file,
            "format": self.format,
            "window": self.window,
            "n_samples": self.n_samples,
            "n_dropped": self.n_dropped,
            "first_dropped": self.first_dropped,
            "dropped": dict(self.dropped),
            "static": self.static,
            "resolution": per(self.resolution) if self.resolution else None,
            "t_start": f(self.t_start),
            "duration": f(self.duration),
            "rate": f(self.rate),
            "jitter": f(self.jitter),
            "dt_min": f(self.dt_min),
            "dt_max": f(self.dt_max),
            "n_gaps": self.n_gaps,
            "q_min": per(self.q_min),
            "q_max": per(self.q_max),
            "velocity_mismatch": per(self.velocity_mismatch),
            "standstill_eps": self.standstill_eps,
            "standstill_share": per(self.standstill_share),
            "tau_max": per(self.tau_max),
            "saturated_share": per(self.saturated_share),
            "clipped_share": per(self.clipped_share),
            "warnings": list(self.warnings),
        }

    def text(self) -> str:
        """A few readable lines."""
        name = self.file + (f"@{self.window}" if self.window else "")
        still = ", ".join(
            f"{j} {100 * s:.0f} %" for j, s in zip(self.joints, self.standstill_share, strict=False)
        )
        lines = [
            f"data {name} ({self.format}): {self.n_samples} samples, {self.duration:.3f} s at "
            f"{self.rate:.6g} Hz (jitter {100 * self.jitter:.2g} %, {self.n_gaps} gaps, "
            f"largest step {1e3 * self.dt_max:.3g} ms)"
            + (
                f", {self.n_dropped} bad rows dropped (first row {self.first_dropped}"
                + "".join(f"; {n} {why}" for why, n in self.dropped.items())
                + ")"
                if self.n_dropped
                else ""
            )
            + (", static" if self.static else ""),
            f"  standstill (|dq| < {self.standstill_eps:g}): {still}",
        ]
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)


class QualityAccumulator:
    """Builds a :class:`DataQuality` from packed row blocks (``add``), then ``finish``."""

    def __init__(
        self,
        layout: Layout,
        joints,
        *,
        file: str,
        format: str,
        window: str | None = None,
        robot=None,
        standstill_eps: float | None = None,
    ):
        """``robot``: an object with ``lower``, ``upper`` [rad or m], shape (nq,), and
        ``effort_limit`` [N m or N], shape (nv,) (a :class:`~manip_id.robot.model.Robot`), whose
        limits the data are checked against; None: no limit checks."""
        self.lay = layout
        nq, nv = layout.nq, layout.nv
        self.q_names = list(joints) if nq == nv else [f"q[{i}]" for i in range(nq)]
        self.out = DataQuality(
            file=file,
            format=format,
            window=window,
            joints=list(joints),
            standstill_eps=STANDSTILL if standstill_eps is None else float(standstill_eps),
        )
        lower, upper, effort_limit = (
            (None, None, None) if robot is None else (robot.lower, robot.upper, robot.effort_limit)
        )
        self.lower = None if lower is None else np.asarray(lower, dtype=float)
        self.upper = None if upper is None else np.asarray(upper, dtype=float)
        lim = None if effort_limit is None else np.asarray(effort_limit, dtype=float)
        self.effort = lim if lim is not None and lim.shape == (nv,) and np.all(lim > 0) else None
        self.n = 0
        self.t0 = self.t_last = math.nan
        self.dt_sum = self.dt_sq = 0.0
        self.dt_min, self.dt_max = math.inf, -math.inf
        self.hist = np.zeros(_BINS.size - 1, dtype=np.int64)
        self.q_min = np.full(nq, np.inf)
        self.q_max = np.full(nq, -np.inf)
        # per bin of the windows' motion (rows) and joint: sums of (Delta q - Delta I)^2,
        # Delta I^2 and Delta q Delta I
        self.fd_sq = np.zeros((_MOTION_BINS, nv))
        self.mid_sq = np.zeros((_MOTION_BINS, nv))
        self.cross = np.zeros((_MOTION_BINS, nv))
        self.step = np.full(nq, np.inf)  # smallest non-zero |q_{k+1} - q_k|
        self.m: int | None = None  # samples per velocity window
        self.integral = np.zeros(nv)  # trapezoid integral of dq up to the last row
        self.mark: tuple[int, np.ndarray, np.ndarray] | None = (
            None  # (index, q, I) at a window start
        )
        self.still = np.zeros(nv, dtype=np.int64)
        self.tau_max = np.zeros(nv)
        self.at_max = np.zeros(nv, dtype=np.int64)
        self.saturated = np.zeros(nv, dtype=np.int64)
        self.last: np.ndarray | None = None

    def add(self, rows: np.ndarray) -> None:
        """Accumulate a block of packed rows (consecutive, after any before)."""
        if not rows.shape[0]:
            return
        s = self.lay.slices
        ext = rows if self.last is None else np.vstack([self.last, rows])
        t = ext[:, 0]
        if self.n == 0:
            self.t0 = float(rows[0, 0])
        self.t_last = float(rows[-1, 0])
        dt = np.diff(t)
        if dt.size:
            self.dt_sum += float(dt.sum())
            self.dt_sq += float(dt @ dt)
            self.dt_min = min(self.dt_min, float(dt.min()))
            self.dt_max = max(self.dt_max, float(dt.max()))
            self.hist += np.histogram(np.log10(np.maximum(dt, 1e-9)), _BINS)[0]
            if self.lay.nq == self.lay.nv:
                self._velocity(ext, dt)
        q = rows[:, s["q"]]
        if ext.shape[0] > 1:
            self.step = np.minimum(self.step, encoder_resolution(ext[:, s["q"]]))
        self.q_min = np.minimum(self.q_min, q.min(axis=0))
        self.q_max = np.maximum(self.q_max, q.max(axis=0))
        dq = rows[:, s["dq"]]
        self.still += (np.abs(dq) < self.out.standstill_eps).sum(axis=0)
        a = np.abs(rows[:, s["tau"]])
        m = a.max(axis=0)
        grew = m > self.tau_max
        self.at_max[grew] = 0
        self.tau_max = np.maximum(self.tau_max, m)
        self.at_max += (a == self.tau_max).sum(axis=0)
        if self.effort is not None:
            self.saturated += (a >= 0.99 * self.effort).sum(axis=0)
        self.n += rows.shape[0]
        self.last = rows[-1:].copy()

    def _velocity(self, ext: np.ndarray, dt: np.ndarray) -> None:
        """Windowed q increments against the integral of dq (see the module docstring).

        ``ext`` holds the previous block's last row (when there is one) and the new
        rows; ``dt`` its steps. Called before ``self.n`` counts the new rows.
        """
        s = self.lay.slices
        q, dq = ext[:, s["q"]], ext[:, s["dq"]]
        if self.m is None:
            self.m = max(1, int(round(VELOCITY_WINDOW / float(np.median(dt)))))
        carried = self.last is not None
        first = self.n - 1 if carried else 0  # global index of ext[0]
        steps = 0.5 * (dq[1:] + dq[:-1]) * dt[:, None]
        integ = self.integral + np.vstack([np.zeros((1, dq.shape[1])), np.cumsum(steps, axis=0)])
        idx = first + np.arange(ext.shape[0])
        pick = np.flatnonzero((idx % self.m == 0) & (np.arange(ext.shape[0]) >= int(carried)))
        if self.mark is None and pick.size:
            self.mark = (int(idx[pick[0]]), q[pick[0]].copy(), integ[pick[0]].copy())
            pick = pick[1:]
        if pick.size and self.mark is not None:
            qs = np.vstack([self.mark[1], q[pick]])
            Is = np.vstack([self.mark[2], integ[pick]])
            dqw, diw = np.diff(qs, axis=0), np.diff(Is, axis=0)
            with np.errstate(divide="ignore"):
                level = np.log10(np.maximum(np.abs(dqw), np.abs(diw)))
            b = np.clip(np.floor(4 * (level + 15)), 0, _MOTION_BINS - 1).astype(np.intp)
            cols = np.broadcast_to(np.arange(dqw.shape[1]), b.shape)
            np.add.at(self.fd_sq, (b, cols), (dqw - diw) ** 2)
            np.add.at(self.mid_sq, (b, cols), diw**2)
            np.add.at(self.cross, (b, cols), dqw * diw)
            self.mark = (int(idx[pick[-1]]), q[pick[-1]].copy(), integ[pick[-1]].copy())
        self.integral = integ[-1].copy()

    def finish(
        self, n_dropped: int = 0, first_dropped: int | None = None, dropped=None
    ) -> DataQuality:
        """The summary, with its warnings; ``dropped``: rows dropped per reason."""
        out = self.out
        out.n_samples, out.n_dropped, out.first_dropped = self.n, n_dropped, first_dropped
        out.dropped = dict(dropped or {})
        out.t_start, out.t_end = self.t0, self.t_last
        self._finish_time(out)
        self._finish_positions(out)
        self._finish_velocity(out)
        self._finish_torques(out)
        return out

    def _finish_time(self, out: DataQuality) -> None:
        """Rate, jitter, extreme steps and gaps (from the histogram of log10 steps)."""
        n = self.n
        if n < 2:
            return
        mean = self.dt_sum / (n - 1)
        var = max(self.dt_sq / (n - 1) - mean * mean, 0.0)
        out.rate = 1.0 / mean if mean > 0 else math.nan
        out.jitter = math.sqrt(var) / mean if mean > 0 else math.nan
        out.dt_min, out.dt_max = self.dt_min, self.dt_max
        cdf = np.cumsum(self.hist)
        median = 10 ** _BINS[int(np.searchsorted(cdf, cdf[-1] / 2)) + 1]
        edge = int(np.searchsorted(_BINS, math.log10(GAP_FACTOR * median)))
        out.n_gaps = int(self.hist[edge:].sum())
        if out.n_gaps:
            out.warnings.append(
                f"{out.n_gaps} gaps in time (steps over {GAP_FACTOR:g} x the median "
                f"{1e3 * median:.3g} ms; largest {1e3 * self.dt_max:.3g} ms)"
            )

    def _finish_positions(self, out: DataQuality) -> None:
        """Position range, degree hint, limit warnings, encoder resolution, static file."""
        n = self.n
        out.q_min, out.q_max = self.q_min.tolist(), self.q_max.tolist()
        if n and np.abs(np.concatenate([self.q_min, self.q_max])).max() > 8 * math.pi:
            out.warnings.append(
                f"positions reach {np.abs(np.concatenate([self.q_min, self.q_max])).max():.1f}: "
                "are they in degrees? manip_id expects radians (meters for prismatic joints)"
            )
        if n and self.lower is not None and self.upper is not None:
            for i, name in enumerate(self.q_names):
                lo, hi = self.lower[i], self.upper[i]
                if np.isfinite(lo) and self.q_min[i] < lo:
                    out.warnings.append(
                        f"joint {name}: positions reach {self.q_min[i]:.4g}, "
                        f"{lo - self.q_min[i]:.3g} below its lower limit {lo:.4g}"
                    )
                if np.isfinite(hi) and self.q_max[i] > hi:
                    out.warnings.append(
                        f"joint {name}: positions reach {self.q_max[i]:.4g}, "
                        f"{self.q_max[i] - hi:.3g} above its upper limit {hi:.4g}"
                    )
        res = self.step  # [rad or m], inf: q never changed
        out.resolution = [float(r) if np.isfinite(r) else math.nan for r in res]
        span = self.q_max - self.q_min
        out.static = bool(n >= 2 and np.all(span <= static_span(res)))

    def _finish_velocity(self, out: DataQuality) -> None:
        """Velocity mismatch per joint over the windows that moved beyond the encoder's steps."""
        res = self.step
        if self.lay.nq == self.lay.nv:
            edges = 10.0 ** (np.arange(_MOTION_BINS) / 4.0 - 15.0)  # lower edge of each bin
            thr = MOTION_STEPS * np.where(np.isfinite(res), res, 0.0)
            use = edges[:, None] >= thr[None, :]  # (bins, nv)
            fd, mid, cross = ((x * use).sum(axis=0) for x in (self.fd_sq, self.mid_sq, self.cross))
        else:
            fd = mid = cross = np.zeros(self.lay.nv)
        with np.errstate(divide="ignore", invalid="ignore"):
            mism = np.sqrt(fd / mid)
        out.velocity_mismatch = mism.tolist() if self.lay.nq == self.lay.nv else []
        if self.lay.nq == self.lay.nv and not out.static:
            for j, name in enumerate(out.joints):
                if mid[j] > 0 and cross[j] < 0:
                    out.warnings.append(
                        f"joint {name}: dq has the opposite sign of the motion of q: "
                        "are velocity columns negated or swapped?"
                    )
                elif np.isfinite(mism[j]) and mism[j] > VELOCITY_MISMATCH:
                    out.warnings.append(
                        f"joint {name}: the integral of dq differs from the motion of q by "
                        f"{100 * mism[j]:.0f} % (RMS over {1e3 * VELOCITY_WINDOW:g} ms windows): "
                        "other units, a lag, or columns of another joint?"
                    )

    def _finish_torques(self, out: DataQuality) -> None:
        """Standstill shares, largest torques, clipped and saturated shares."""
        n, joints = self.n, out.joints
        out.standstill_share = (self.still / max(n, 1)).tolist()
        out.tau_max = self.tau_max.tolist()
        clipped = self.at_max / max(n, 1)
        out.clipped_share = clipped.tolist()
        for j, name in enumerate(joints):
            if out.static:  # a still robot's torque sits at one value: not a clipped signal
                break
            if clipped[j] > CLIPPED_SHARE and self.at_max[j] > 2 and self.tau_max[j] > 0:
                out.warnings.append(
                    f"joint {name}: {100 * clipped[j]:.2g} % of the torques sit at the "
                    f"largest value {self.tau_max[j]:.4g}: saturated or clipped?"
                )
        if self.effort is not None:
            sat = self.saturated / max(n, 1)
            out.saturated_share = sat.tolist()
            for j, name in enumerate(joints):
                if sat[j] > 0:
                    out.warnings.append(
                        f"joint {name}: {100 * sat[j]:.2g} % of the torques at >= 99 % of the "
                        f"effort limit {self.effort[j]:.4g}"
                    )
