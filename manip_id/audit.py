"""The log auditor: the user's data mistakes, found against the nominal model before a fit.

For each file (its window, bad rows and torque scale applied as the fit would see
them) and each joint ``j``, the measured torque is compared with the nominal one
``tau0 = rnea(q, dq, ddq)`` of the robot's own model (ddq from the file, or from
:func:`manip_id.signals.preprocess` when the file has none; torques filtered alike).
On the rows of the motion stream ``k`` and the torque stream ``k + L``::

    tau_j[k + L] = s_j tau0_j[k] + f_v dq_j[k] + f_c sgn_eps(dq_j[k]) + o_j + e[k]

least squares over integer lags ``|L| <= max_delay / dt`` picks the lag of least
residual, refined to a sub-sample ``delay`` [s] by the parabola through its
neighbours; at that lag a Huber-weighted fit gives the robust ``scale`` ``s_j``
(measured over nominal torque: about 0.1 for currents of a drive whose gain is 10
N m/A, -1 for a flipped sign) and the ``offset`` ``o_j / s_j`` [N m]. The friction
columns keep unmodelled friction from posing as a delay (viscous friction moves
with dq as the derivative of the gravity torque does). A scale counts as
determined when the nominal column explains at least :data:`EXPLAINED_MIN` of the
torque variance the other columns leave.

Also per file: the time unit (a rate outside 1 Hz .. 100 kHz is refused, naming
the likely unit), positions (degrees, an offset against the limits, wrap-around),
the standstill share per joint (``|dq_j| < eps``) and the rest at the file's edges
(the window :attr:`FileAudit.kept` that ``--trim-standstill`` keeps), static files
(no joint moves beyond its encoder's resolution: "used for gravity and offset
only"), and the bad rows dropped. Findings are sentences; :class:`Audit` holds
them, its compact :meth:`~Audit.table` and its JSON (:meth:`~Audit.to_dict`).
The audit holds one file's rows in memory at a time.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from .datasets import FileSpec, RowCounts, Window, iter_rows, open_source, parse_file_spec
from .datasets.adjust import check_rate
from .datasets.quality import STANDSTILL, encoder_resolution, static_span
from .datasets.stream import READ_CHUNK, collect, torque_scale_vector
from .errors import DataError, InputError
from .regressor import regressor
from .robot import Robot
from .signals import DEFAULT_CUTOFF, preprocess

#: Measured / nominal torque ratios outside [1 / FAR, FAR] are reported (currents, gears).
FAR = 2.0
#: Share of the residual torque variance the nominal column must explain for a scale.
EXPLAINED_MIN = 0.3
#: A delay longer than this many sampling steps is reported ...
DELAY_STEPS = 1.5
#: ... when it removes at least this share of the held-out torque error.
DELAY_GAIN = 0.05
#: Rest at a file's start or end longer than this [s] is reported (``--trim-standstill``).
EDGE_REST = 1.0
#: A joint at rest on more than this share of the rows is reported.
REST_SHARE = 0.5
#: Huber threshold in robust standard deviations (MAD) and iterations of the robust fit.
HUBER, IRLS_STEPS = 1.345, 8


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
            "scale": _num(self.scale),
            "delay": _num(self.delay),
            "offset": _num(self.offset),
            "standstill": _num(self.standstill),
            "explained": _num(self.explained),
            "own_delay": _num(self.own_delay),
        }


@dataclass
class FileAudit:
    """The audit of one file: its joints, its findings (sentences) and what to pass.

    ``suggestions`` holds the options the findings recommend: ``torque_scale`` (one
    per joint), ``delay`` [s] (one per joint), ``trim_standstill`` (bool). ``kept``:
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
            "rate": _num(self.rate),
            "static": self.static,
            "findings": list(self.findings),
            "joints": [j.to_dict() for j in self.joints],
            "delay_gain": _num(self.delay_gain),
            "rest": {"start": _num(self.rest[0]), "end": _num(self.rest[1])},
            "kept_window": None if self.kept is None else str(self.kept),
            "dropped": dict(self.dropped),
            "suggestions": dict(self.suggestions),
        }


@dataclass
class Audit:
    """The audit of a run's files (see the module docstring)."""

    robot: str
    files: list[FileAudit]

    @property
    def findings(self) -> list[str]:
        """Every finding, prefixed with its file."""
        return [f"{fa.file}: {f}" for fa in self.files for f in fa.findings]

    def to_dict(self) -> dict:
        return {"robot": self.robot, "files": [fa.to_dict() for fa in self.files]}

    def trimmed(self) -> list[FileSpec]:
        """The files with the windows ``--trim-standstill`` keeps (others as they were)."""
        return [fa.spec if fa.kept is None else fa.spec.with_window(fa.kept) for fa in self.files]

    def table(self) -> str:
        """One compact table: a row per file and joint, then the findings."""
        head = (
            f"{'file':<28} {'rows':>8} {'rate [Hz]':>9}  {'joint':<22} {'scale':>7} "
            f"{'delay [ms]':>10} {'offset':>8} {'rest':>5}"
        )
        lines = [f"audit against the nominal model of {self.robot}", head]
        for fa in self.files:
            name = fa.file if len(fa.file) <= 28 else "..." + fa.file[-25:]
            for k, j in enumerate(fa.joints):
                left = f"{name:<28} {fa.n_rows:>8} {fa.rate:>9.4g}" if k == 0 else " " * 47
                lines.append(
                    f"{left}  {j.joint[-22:]:<22} {_fmt(j.scale, '+.3f'):>7} "
                    f"{_fmt(None if j.delay is None else 1e3 * j.delay, '+.2f'):>10} "
                    f"{_fmt(j.offset, '+.3g'):>8} {100 * j.standstill:>4.0f}%"
                )
            lines += [f"  - {f}" for f in fa.findings] or ["  - no finding"]
        return "\n".join(lines)


def _num(x) -> float | None:
    return None if x is None or not math.isfinite(float(x)) else float(x)


def _fmt(x, spec: str) -> str:
    return "n/d" if x is None else format(x, spec)


# ---------------------------------------------------------------- reading
def _read(robot: Robot, spec: FileSpec, options: AuditOptions):
    """``(dataset, counts, rate)`` of the rows a fit sees; refuses an implausible rate."""
    try:
        src = open_source(spec, joint_names=list(robot.dof_names))
    except DataError as exc:
        msg = str(exc)
        raise DataError(msg if str(spec.path) in msg else f"{spec.label}: {msg}") from exc
    lay = src.layout
    if lay.nq != robot.nq or lay.nv != robot.nv:
        raise DataError(
            f"{spec.label}: the data have {lay.nv} joints ({lay.nq} positions) but robot "
            f"{robot.name!r} has nq={robot.nq}, nv={robot.nv}"
        )
    first = next(iter(src.chunks(4096, 0, 4096)), None)  # before the value checks:
    if first is not None:  # stamps in ns would be refused as implausible seconds
        t = first[:, 0][np.isfinite(first[:, 0])]
        steps = np.diff(t)
        if steps.size and np.median(steps) > 0:
            check_rate(float(np.median(steps)), spec.label, spec.time_unit)
    counts = RowCounts()
    scale = torque_scale_vector(options.torque_scale, lay.nv, "--torque-scale")
    rows = iter_rows(
        src,
        spec.window,
        torque_scale=scale,
        drop_bad_rows=options.drop_bad_rows,
        chunk=options.read_chunk,
        counts=counts,
    )
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # degrees: a finding of the audit
            ds = collect(rows, lay, src.joint_names)
    except DataError as exc:
        msg = str(exc)
        raise DataError(msg if str(spec.path) in msg else f"{spec.label}: {msg}") from exc
    step = float(np.median(np.diff(ds.t)))
    return ds, counts, check_rate(step, spec.label, spec.time_unit), src


def audit_file(robot: Robot, spec, options: AuditOptions | None = None) -> FileAudit:
    """The audit of one file (see the module docstring).

    Parameters
    ----------
    robot: the robot whose nominal model is the reference.
    spec: a :class:`~manip_id.datasets.FileSpec` or its text ``PATH[@WINDOW]``.
    options: :class:`AuditOptions`.

    Raises
    ------
    DataError: the file cannot be read, does not fit the robot, or its time stamps give
        an implausible rate (the message names the likely unit).
    """
    spec = parse_file_spec(spec)
    options = options or AuditOptions()
    ds, counts, rate, src = _read(robot, spec, options)
    eps = STANDSTILL if options.standstill is None else float(options.standstill)
    joints = list(robot.dof_names)
    still = np.abs(ds.dq) < eps  # (N, nv)
    res = encoder_resolution(ds.q)
    static = bool(np.all(ds.q.max(axis=0) - ds.q.min(axis=0) <= static_span(res)))
    findings: list[str] = []
    suggestions: dict = {}
    if counts.n_dropped:
        why = ", ".join(f"{n} {r}" for r, n in counts.reasons.items())
        findings.append(
            f"{counts.n_dropped} bad rows dropped ({why}; first row {counts.first_dropped})"
        )
    findings += _position_findings(robot, ds.q)
    gain = None
    if static:
        findings.append("static: used for gravity and offset only")
        audits = _static_fits(robot, ds, still)
        rest, kept = (0.0, 0.0), None
    else:
        audits, gain = _motion_fits(robot, ds, still, eps, options, findings)
        rest, kept = _edges(ds, still, spec, counts)
        if max(rest) > EDGE_REST:
            findings.append(
                f"at rest for {rest[0]:.3g} s at the start and {rest[1]:.3g} s at the end: "
                f"--trim-standstill keeps {kept}"
            )
            suggestions["trim_standstill"] = True
        else:
            kept = None
        share = still.mean(axis=0)
        for j in np.flatnonzero(share > REST_SHARE):
            findings.append(f"joint {joints[j]} at rest on {100 * share[j]:.0f} % of the rows")
    findings += _torque_findings(audits, 1.0 / rate, gain, suggestions, options.currents)
    return FileAudit(
        spec=spec,
        n_rows=ds.n_samples,
        rate=rate,
        static=static,
        joints=audits,
        findings=findings,
        rest=rest,
        kept=kept,
        dropped=dict(counts.reasons),
        suggestions=suggestions,
        delay_gain=gain,
    )


def audit_files(robot: Robot, files, options: AuditOptions | None = None, *, window=None) -> Audit:
    """:func:`audit_file` for every file of ``files`` (specs or their texts), in order.

    ``window`` (text or :class:`~manip_id.datasets.Window`) applies to each file that has none.
    """
    if isinstance(files, (str, FileSpec)) or not hasattr(files, "__iter__"):
        files = [files]
    specs = [parse_file_spec(f, window=window) for f in files]
    if not specs:
        raise InputError("no data files given")
    return Audit(robot.name, [audit_file(robot, s, options) for s in specs])


# ---------------------------------------------------------------- motion
def _edges(ds, still: np.ndarray, spec: FileSpec, counts: RowCounts):
    """``((rest_start, rest_end) [s], kept window)`` from the rows where some joint moves."""
    moving = np.flatnonzero(~still.all(axis=1))
    if not moving.size:
        return (ds.duration, ds.duration), None
    a, b = int(moving[0]), int(moving[-1])
    rest = (float(ds.t[a] - ds.t[0]), float(ds.t[-1] - ds.t[b]))
    w = spec.window
    if w is not None and w.unit == "index":
        if counts.n_dropped:
            raise InputError(
                f"{spec.label}: --trim-standstill on a row window with dropped bad rows: "
                "give the window in seconds"
            )
        start = w.start or 0
        return rest, Window(start + a, start + b + 1, "index")
    t0 = counts.t_file_start if counts.t_file_start is not None else float(ds.t[0])
    step = float(np.median(np.diff(ds.t)))
    return rest, Window(float(ds.t[a] - t0), float(ds.t[b] - t0 + 0.5 * step), "s")


def _nominal(robot: Robot, q, dq, ddq) -> np.ndarray:
    """``rnea`` of the robot's own model (URDF inertias and armature), shape (N, nv)."""
    model = robot.model
    data = model.createData()
    out = np.empty((q.shape[0], robot.nv))
    for k in range(q.shape[0]):
        out[k] = pin.rnea(model, data, q[k], dq[k], ddq[k])
    return out


def _motion_fits(robot, ds, still, eps: float, options: AuditOptions, findings: list[str]):
    """``(joints, delay_gain)`` of a moving file: per joint :class:`JointAudit`, and the
    share of the held-out error the file's delay removes (None: not searched)."""
    proc = ds
    if ds.ddq is None:
        cutoff = DEFAULT_CUTOFF if options.cutoff is None else options.cutoff
        try:
            proc = preprocess(ds, cutoff=cutoff)
        except (InputError, DataError) as exc:
            findings.append(f"torques not audited: {exc}")
            return [_joint(robot, j, still) for j in range(ds.nv)], None
    nom = _nominal(robot, proc.q, proc.dq, proc.ddq)
    step = float(np.median(np.diff(proc.t)))
    max_lag = min(int(round(options.max_delay / step)), proc.n_samples // 10)
    args = [(nom[:, j], proc.tau[:, j], proc.dq[:, j], eps, max_lag) for j in range(ds.nv)]
    first = [_fit_joint(*a, 0.0) for a in args]
    gains = np.array([1.0 if f[0] is None else f[0] for f in first])
    common, gain, own = _lags(robot, proc, eps, max_lag, gains)
    out = []
    for j in range(ds.nv):
        scale, offset, explained = _fit_joint(*args[j], common)
        out.append(
            _joint(
                robot,
                j,
                still,
                scale=scale,
                delay=None if common is None else float(common * step),
                offset=offset,
                explained=explained,
                own_delay=None if own[j] is None else float(own[j] * step),
            )
        )
    return out, (None if common is None else gain)


def _joint(robot, j: int, still: np.ndarray, **fields) -> JointAudit:
    base = {"scale": None, "delay": None, "offset": None, "explained": None, "own_delay": None}
    return JointAudit(
        robot.dof_names[j], standstill=float(still[:, j].mean()), **{**base, **fields}
    )


#: Rows of the motion stream the delay search fits (evenly spaced over the file).
LAG_ROWS = 12000
#: Rows per block of the two interleaved halves of the delay search's cross-validation.
LAG_BLOCK = 200


def _lags(robot, proc, eps: float, max_lag: int, gains: np.ndarray):
    """``(common, gain, own)``: the lag [samples] of the whole torque stream, the share of
    the held-out error it removes against lag 0, and per joint the lag of its own torque
    (the others at the common lag); lags are None when not determined.

    The lag is the one whose torques (each divided by its scale at lag 0, ``gains``) one
    rigid-body model predicts best on held-out rows.
    The model is the robot's full regressor with parameters shared by all joints, plus
    per joint ``dq_j``, ``sgn_eps(dq_j)`` and 1 (friction, offset). The rows are cut into
    two interleaved halves of :data:`LAG_BLOCK` rows; the parameters fitted on one half
    for lags ``L`` (``beta = G^+ b``, ``G = sum_j Y_j^T Y_j`` fixed by the motion stream,
    ``b = sum_j Y_j^T tau_j[k + L_j]``) predict the other, and the two prediction errors
    add up (two-fold cross-validation: an in-sample residual lets the lag fit the model's
    own errors). The common lag is swept for all joints at once; each joint's own lag with
    the others held at it. Both are refined to a sub-sample by the parabola through the
    neighbours of the best lag.
    """
    n, nv = proc.n_samples, robot.nv
    if max_lag < 1:
        return None, 0.0, [None] * nv
    k = np.arange(max_lag, n - max_lag)
    k = k[:: max(1, k.size // LAG_ROWS)]
    Y = regressor(robot, proc.q[k], proc.dq[k], proc.ddq[k])  # (N', nv, p)
    F = np.zeros((k.size, nv, 3 * nv))
    for j in range(nv):
        dq = proc.dq[k, j]
        F[:, j, 3 * j : 3 * j + 3] = np.column_stack(
            [dq, np.where(np.abs(dq) >= eps, np.sign(dq), 0.0), np.ones(k.size)]
        )
    Y = np.concatenate([Y, F], axis=2)
    norm = np.sqrt(np.einsum("njc,njc->c", Y, Y))
    Y = Y[:, :, norm > 0] / norm[norm > 0]
    sweep = np.arange(-max_lag, max_lag + 1)
    half = (np.arange(k.size) // LAG_BLOCK) % 2 == 0
    tau = proc.tau / gains  # currents and flipped signs undone: one model fits all joints
    parts = [_lag_sums(Y[m], tau, k[m], sweep) for m in (half, ~half)]
    curve = sum(_held_out(parts[a], parts[1 - a], None, None) for a in (0, 1))  # SSE
    common = _vertex(curve)
    gain = float((curve[max_lag] - curve.min()) / curve[max_lag]) if curve[max_lag] > 0 else 0.0
    at = np.full(nv, max_lag if common is None else int(round(common)))  # sweep indices
    own = [
        _vertex(sum(_held_out(parts[a], parts[1 - a], j, at) for a in (0, 1))) for j in range(nv)
    ]
    shift = -max_lag
    return (
        None if common is None else common + shift,
        gain,
        [None if x is None else x + shift for x in own],
    )


def _vertex(curve: np.ndarray) -> float | None:
    """Index of the minimum of ``curve``, refined by the parabola through its neighbours;
    None when the curve is flat."""
    c = curve
    if c.max() - c.min() <= 1e-9 * max(abs(c.max()), 1e-300):
        return None
    i = int(np.argmin(c))
    frac = 0.0
    if 0 < i < c.size - 1:
        den = c[i - 1] - 2 * c[i] + c[i + 1]
        if den > 0:
            frac = float(np.clip(0.5 * (c[i - 1] - c[i + 1]) / den, -0.5, 0.5))
    return i + frac


def _lag_sums(Y: np.ndarray, tau: np.ndarray, k: np.ndarray, sweep: np.ndarray):
    """``(G, G^+, B, yy)`` of rows ``k``: ``B[j, :, i] = Y_j^T tau_j[k + sweep_i]``,
    ``yy[j, i] = ||tau_j[k + sweep_i]||^2``."""
    nv = Y.shape[1]
    G = np.einsum("njc,njd->cd", Y, Y)
    Gp = np.linalg.pinv(G, rcond=1e-10, hermitian=True)
    idx = k[:, None] + sweep[None, :]
    B = np.stack([Y[:, j, :].T @ tau[idx, j] for j in range(nv)])
    yy = np.stack([np.sum(tau[idx, j] ** 2, axis=0) for j in range(nv)])
    return G, Gp, B, yy


def _held_out(train, valid, j: int | None, at: np.ndarray | None) -> np.ndarray:
    """Prediction error on ``valid`` of the fit on ``train`` over the lags: of joint ``j``
    (the other joints at the indices ``at``), or of all joints together (``j`` None); up to
    a constant, shape (lags,)."""
    _, Gp, Bt, yyt = train
    Gv, _, Bv, yyv = valid
    if j is None or at is None:
        bt, bv, yy = Bt.sum(axis=0), Bv.sum(axis=0), yyv.sum(axis=0)
    else:
        nv = Bt.shape[0]
        others = np.flatnonzero(np.arange(nv) != j)
        bt = Bt[others, :, at[others]].sum(axis=0)[:, None] + Bt[j]  # (c, lags)
        bv = Bv[others, :, at[others]].sum(axis=0)[:, None] + Bv[j]
        yy = yyv[j]
    beta = Gp @ bt
    return yy - 2 * np.einsum("cl,cl->l", bv, beta) + np.einsum("cl,cd,dl->l", beta, Gv, beta)


def _static_fits(robot, ds, still) -> list[JointAudit]:
    """The joints of a static file: the gravity torque alone cannot tell a scale from an
    offset, so the scale is left undetermined and the offset is the mean of ``tau - g(q)``."""
    nom = _nominal(robot, ds.q, np.zeros_like(ds.dq), np.zeros_like(ds.dq))
    return [
        _joint(robot, j, still, offset=float(np.mean(ds.tau[:, j] - nom[:, j])))
        for j in range(ds.nv)
    ]


def _fit_joint(nom, meas, dq, eps: float, max_lag: int, lag: float | None):
    """``(scale, offset, explained)`` of one joint at the (rounded) ``lag``: the robust fit
    of the measured torque on the nominal one, friction and offset (module docstring)."""
    n = nom.shape[0]
    L = 0 if lag is None else int(round(lag))
    k = np.arange(max_lag, n - max_lag)
    sgn = np.where(np.abs(dq) >= eps, np.sign(dq), 0.0)
    X = np.column_stack([nom[k], dq[k], sgn[k], np.ones(k.size)])
    col = np.abs(X).max(axis=0)
    col[col == 0] = 1.0
    y = meas[k + L]
    coef = _huber(X / col, y) / col
    s, offset = float(coef[0]), float(coef[3])
    full = np.linalg.lstsq(X, y, rcond=None)[0]
    rest = np.linalg.lstsq(X[:, 1:], y, rcond=None)[0]
    sse_with = float(np.sum((y - X @ full) ** 2))
    sse_without = float(np.sum((y - X[:, 1:] @ rest) ** 2))
    explained = 1.0 - sse_with / sse_without if sse_without > 0 else None
    if explained is None or explained < EXPLAINED_MIN or s == 0:
        return None, offset, explained
    return s, offset / s, explained


def _huber(X: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Huber-weighted least squares (IRLS, MAD scale) of ``y ~ X c``, shape (p,)."""
    w = np.ones(y.shape[0])
    c = np.linalg.lstsq(X, y, rcond=None)[0]
    for _ in range(IRLS_STEPS):
        r = y - X @ c
        mad = 1.4826 * float(np.median(np.abs(r - np.median(r))))
        if not mad > 1e-12 * max(float(np.abs(y).max()), 1e-300):
            break
        a = np.abs(r) / (HUBER * mad)
        w = np.where(a <= 1, 1.0, 1.0 / np.maximum(a, 1e-300))
        sw = np.sqrt(w)
        c = np.linalg.lstsq(X * sw[:, None], y * sw, rcond=None)[0]
    return c


# ---------------------------------------------------------------- findings
def _torque_findings(
    audits: list[JointAudit], step: float, gain, suggestions: dict, currents: bool = False
) -> list[str]:
    """Scale, sign and delay findings; fills ``suggestions``."""
    out: list[str] = []
    gains, flagged = [], False
    for j in audits:
        s = j.scale
        if s is not None and s < 0:
            out.append(f"sign flipped on joint {j.joint} (measured / nominal torque {s:.3g})")
        if currents:
            continue
        if s is not None and not 1.0 / FAR <= abs(s) <= FAR:
            out.append(
                f"joint {j.joint}: measured / nominal torque {s:.3g}: currents or a gear ratio?"
            )
        bad = s is not None and (s < 0 or not 1.0 / FAR <= abs(s) <= FAR)
        flagged |= bad
        gains.append(float(f"{1.0 / s:.4g}") if bad and s is not None else 1.0)
    if flagged:
        suggestions["torque_scale"] = gains
        out.append("try --torque-scale " + ",".join(f"{g:g}" for g in gains))
    d = next((j.delay for j in audits if j.delay is not None), None)  # the file's
    if d is not None and abs(d) > DELAY_STEPS * step and gain is not None and gain >= DELAY_GAIN:
        word = "lags" if d > 0 else "leads"
        out.append(
            f"the torque stream {word} the motion stream by {1e3 * abs(d):.3g} ms "
            f"({abs(d) / step:.3g} samples): try --delay {d:.4g}"
        )
        suggestions["delay"] = float(f"{d:.4g}")
    return out


def _position_findings(robot: Robot, q: np.ndarray) -> list[str]:
    """Degrees, an offset against the limits, wrap-around (1-DoF joints with nq == nv)."""
    if robot.nq != robot.nv:
        return []
    out: list[str] = []
    lo, hi = robot.lower, robot.upper
    for j, name in enumerate(robot.dof_names):
        if robot.is_prismatic(j):
            continue
        qj = q[:, j]
        top = float(np.abs(qj).max())
        bounded = math.isfinite(lo[j]) and math.isfinite(hi[j]) and hi[j] - lo[j] < 1e3
        jumps = int(np.sum(np.abs(np.diff(qj)) > math.pi))
        if jumps:
            out.append(
                f"joint {name}: positions jump by about 2 pi {jumps} times: wrap-around? "
                "unwrap them (numpy.unwrap)"
            )
        if top > 2.2 * math.pi:
            inside = bounded and lo[j] - 0.05 <= np.radians(qj).min() <= np.radians(qj).max()
            inside = inside and np.radians(qj).max() <= hi[j] + 0.05
            out.append(
                f"joint {name}: positions reach {top:.4g}: degrees? manip_id expects radians"
                + (" (in radians they fit the limits)" if inside else "")
            )
        elif bounded and not jumps:
            below, above = lo[j] - qj.min(), qj.max() - hi[j]
            span = qj.max() - qj.min()
            if max(below, above) > 0.05 * (hi[j] - lo[j]) and span <= hi[j] - lo[j]:
                shift = below if below > 0 else -above
                out.append(
                    f"joint {name}: positions {qj.min():.3g} .. {qj.max():.3g} leave the limits "
                    f"[{lo[j]:.3g}, {hi[j]:.3g}] while their span fits: a zero offset? "
                    f"(adding {shift:+.3g} rad brings them inside)"
                )
    return out
