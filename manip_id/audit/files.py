"""One file audited: its rows read as the fit sees them, then each check in turn."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..datasets import (
    FileSpec,
    RowCache,
    RowCounts,
    Window,
    iter_rows,
    open_source,
    parse_file_spec,
)
from ..datasets.adjust import check_rate
from ..datasets.quality import STANDSTILL, encoder_resolution, static_span
from ..datasets.stream import torque_scale_vector
from ..errors import DataError, InputError
from ..robot.model import Robot
from ..signals import DEFAULT_CUTOFF, preprocess
from ..signals.bandwidth import choose_cutoff
from ..signals.butterworth import load_kernels
from .delay import stream_lags
from .findings import position_findings, torque_findings
from .fits import fit_joint, nominal_torque
from .reading import AuditRows, read_pass
from .report import Audit, AuditOptions, FileAudit, JointAudit

#: Rest at a file's start or end longer than this [s] is reported (``--trim-standstill``).
EDGE_REST = 1.0
#: A joint at rest on more than this share of the rows is reported.
REST_SHARE = 0.5
#: The first rows whose stamps are checked for a plausible rate before the rows are read.
RATE_ROWS = 4096


def _read(robot: Robot, spec: FileSpec, options: AuditOptions, eps: float, cache):
    """``(rows, counts, rate)`` of the rows a fit sees (:class:`AuditRows`); refuses an
    implausible rate."""
    try:
        src = open_source(spec, joint_names=list(robot.dof_names), cache=cache)
    except DataError as exc:
        msg = str(exc)
        raise DataError(msg if str(spec.path) in msg else f"{spec.label}: {msg}") from exc
    lay = src.layout
    if lay.nq != robot.nq or lay.nv != robot.nv:
        raise DataError(
            f"{spec.label}: the data have {lay.nv} joints ({lay.nq} positions) but robot "
            f"{robot.name!r} has nq={robot.nq}, nv={robot.nv}"
        )
    # the first rows' rate before the value checks: stamps in ns would be refused as
    # implausible seconds (with a cache: the first block of the pass below, recorded once)
    head: tuple = (RATE_ROWS, 0, RATE_ROWS)
    if cache is not None:
        w = spec.window
        span = (0, None) if w is None or w.unit != "index" else (w.start or 0, w.stop)
        head = (options.read_chunk, *span)
    first = next(iter(src.chunks(*head)), None)
    if first is not None:
        t = first[:RATE_ROWS, 0][np.isfinite(first[:RATE_ROWS, 0])]
        steps = np.diff(t)
        if steps.size and np.median(steps) > 0:
            check_rate(float(np.median(steps)), spec.label, spec.time_unit)
    if not lay.has_ddq:  # the central rows will be filtered: load the filter first
        load_kernels()  # (its memory taken before the read's transients, not on top)
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
        ds = read_pass(rows, lay, src.joint_names, eps, getattr(src, "n_rows", None))
    except DataError as exc:
        msg = str(exc)
        raise DataError(msg if str(spec.path) in msg else f"{spec.label}: {msg}") from exc
    step = float(np.median(np.diff(ds.t)))
    return ds, counts, check_rate(step, spec.label, spec.time_unit)


def audit_file(
    robot: Robot, spec, options: AuditOptions | None = None, *, cache: RowCache | None = None
) -> FileAudit:
    """The audit of one file (see the module docstring).

    Parameters
    ----------
    robot: the robot whose nominal model is the reference.
    spec: a :class:`~manip_id.datasets.FileSpec` or its text ``PATH[@WINDOW]``.
    options: :class:`AuditOptions`.
    cache: a :class:`~manip_id.datasets.RowCache` that keeps the parsed rows of a slow
        format (CSV, ROS bags) for the run's later passes (the scan before the fit).

    Raises
    ------
    DataError: the file cannot be read, does not fit the robot, or its time stamps give
        an implausible rate (the message names the likely unit).
    """
    spec = parse_file_spec(spec)
    options = options or AuditOptions()
    if robot.terms.temperature:  # a slow drift of the friction the audit's fits do without
        robot = robot.with_terms(replace(robot.terms, temperature=False))
    eps = STANDSTILL if options.standstill is None else float(options.standstill)
    ds, counts, rate = _read(robot, spec, options, eps, cache)
    joints = list(robot.dof_names)
    still = ds.still  # (nv,) shares of the rows at rest
    res = encoder_resolution(ds.q)
    static = bool(np.all(ds.q.max(axis=0) - ds.q.min(axis=0) <= static_span(res)))
    findings: list[str] = []
    suggestions: dict = {}
    if counts.n_dropped:
        why = ", ".join(f"{n} {r}" for r, n in counts.reasons.items())
        findings.append(
            f"{counts.n_dropped} bad row{'s' if counts.n_dropped > 1 else ''} dropped "
            f"({why}; first row {counts.first_dropped})"
        )
    findings += position_findings(robot, ds.q)
    gain = None
    if static:
        findings.append("static: used for gravity and offset only")
        audits = _static_fits(robot, ds, still)
        rest, kept = (0.0, 0.0), None
    else:
        ds.q = np.empty((0, ds.q.shape[1]))  # every row's positions used: freed before the fits
        audits, gain = _motion_fits(robot, ds.central, still, eps, options, findings)
        rest, kept = _edges(ds, still, spec, counts)
        if max(rest) > EDGE_REST:
            findings.append(
                f"at rest for {rest[0]:.3g} s at the start and {rest[1]:.3g} s at the end: "
                f"--trim-standstill keeps {kept}"
            )
            suggestions["trim_standstill"] = True
        else:
            kept = None
        for j in np.flatnonzero(still > REST_SHARE):
            findings.append(f"joint {joints[j]} at rest on {100 * still[j]:.0f} % of the rows")
    findings += torque_findings(audits, 1.0 / rate, gain, suggestions, options.currents)
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


def audit_files(
    robot: Robot,
    files,
    options: AuditOptions | None = None,
    *,
    window=None,
    cache: RowCache | None = None,
) -> Audit:
    """:func:`audit_file` for every file of ``files`` (specs or their texts), in order.

    ``window`` (text or :class:`~manip_id.datasets.Window`) applies to each file that has
    none; ``cache``: see :func:`audit_file`. A file that cannot be read does not stop the
    others: it is named in :attr:`Audit.failed` with its reason (:meth:`Audit.check`
    raises for them all at once); when no file can be read, the one error names each.
    """
    if isinstance(files, (str, FileSpec)) or not hasattr(files, "__iter__"):
        files = [files]
    specs = [parse_file_spec(f, window=window) for f in files]
    if not specs:
        raise InputError("no data files given")
    done, failed = [], {}
    for s in specs:
        try:
            done.append(audit_file(robot, s, options, cache=cache))
        except DataError as exc:
            failed[s.label] = str(exc)
    audit = Audit(robot.name, done, failed)
    if not done:
        if len(failed) == 1:
            raise DataError(next(iter(failed.values())))
        audit.check()
    return audit


# ---------------------------------------------------------------- motion
def _edges(ds: AuditRows, still: np.ndarray, spec: FileSpec, counts: RowCounts):
    """``((rest_start, rest_end) [s], kept window)`` from the rows where some joint moves."""
    if ds.moving is None:
        return (ds.duration, ds.duration), None
    a, b = ds.moving
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


def _motion_fits(robot, ds, still, eps: float, options: AuditOptions, findings: list[str]):
    """``(joints, delay_gain)`` of a moving file: per joint :class:`JointAudit`, and the
    share of the held-out error the file's delay removes (None: not searched). The fits
    use ``ds``, the central :data:`FIT_ROWS` rows of a longer file (the standstill
    shares ``still`` all rows)."""
    proc = ds
    if ds.ddq is None:
        cutoff = DEFAULT_CUTOFF if options.cutoff is None else options.cutoff
        try:
            if cutoff == "auto":  # from the file's velocity spectrum (signals.bandwidth)
                cutoff = choose_cutoff(ds.t, robot.dofs.angles(ds.q)).cutoff
            proc = preprocess(ds, cutoff=float(cutoff))
        except (InputError, DataError) as exc:
            findings.append(f"torques not audited: {exc}")
            return [_joint(robot, j, still) for j in range(ds.nv)], None
    nom = nominal_torque(robot, proc.q, proc.dq, proc.ddq)
    step = float(np.median(np.diff(proc.t)))
    max_lag = min(int(round(options.max_delay / step)), proc.n_samples // 10)
    args = [(nom[:, j], proc.tau[:, j], proc.dq[:, j], eps, max_lag) for j in range(ds.nv)]
    first = [fit_joint(*a, 0.0) for a in args]
    gains = np.array([1.0 if f[0] is None else f[0] for f in first])
    common, gain, own = stream_lags(robot, proc, eps, max_lag, gains)
    out = []
    for j in range(ds.nv):
        scale, offset, explained = fit_joint(*args[j], common)
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
    return JointAudit(robot.dof_names[j], standstill=float(still[j]), **{**base, **fields})


def _static_fits(robot, ds: AuditRows, still) -> list[JointAudit]:
    """The joints of a static file: the gravity torque alone cannot tell a scale from an
    offset, so the scale is left undetermined and the offset is the mean of ``tau - g(q)``."""
    zero = np.zeros((ds.n_samples, robot.nv))
    g = nominal_torque(robot, ds.q, zero, zero).mean(axis=0)
    return [_joint(robot, j, still, offset=float(ds.tau_mean[j] - g[j])) for j in range(robot.nv)]
