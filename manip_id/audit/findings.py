"""The audit's findings: sentences from the per-joint figures and the positions."""

from __future__ import annotations

import math

import numpy as np

from ..robot.model import Robot
from .report import JointAudit

#: Measured / nominal torque ratios outside [1 / FAR, FAR] are reported (currents, gears).
FAR = 2.0
#: Median step of q [rad] below which positions are a smooth time series (wrap-around
#: is looked for only there: jumps of 2 pi +- 0.5 between neighbours).
SMOOTH_STEP = 0.1
#: A delay longer than this many sampling steps is reported ...
DELAY_STEPS = 1.5
#: ... when it removes at least this share of the held-out torque error.
DELAY_GAIN = 0.05


def torque_findings(
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
        gains.append(None if s is None else float(f"{1.0 / s:.4g}") if bad else 1.0)
    if flagged:
        suggestions["torque_scale"] = gains
        out.append("try --torque-scale " + ",".join("?" if g is None else f"{g:g}" for g in gains))
        unknown = [j.joint for j, g in zip(audits, gains, strict=True) if g is None]
        if unknown:  # a 1 there would keep their amperes: say so instead
            out.append(
                f"scale not determined for {', '.join(unknown)} (the nominal model explains "
                "too little of their torque, or they hardly move): give their gains in place "
                "of ? (the drive's torque constant times the gear ratio [N m / A]; "
                "manip-id drive-gains measures them)"
            )
    d = next((j.delay for j in audits if j.delay is not None), None)  # the file's
    if d is not None and abs(d) > DELAY_STEPS * step and gain is not None and gain >= DELAY_GAIN:
        word = "lags" if d > 0 else "leads"
        out.append(
            f"the torque stream {word} the motion stream by {1e3 * abs(d):.3g} ms "
            f"({abs(d) / step:.3g} samples): try --delay {d:.4g}"
        )
        suggestions["delay"] = float(f"{d:.4g}")
    return out


def position_findings(robot: Robot, q: np.ndarray) -> list[str]:
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
        steps = np.abs(np.diff(qj))
        smooth = steps.size > 0 and float(np.median(steps)) < SMOOTH_STEP  # a time series
        jumps = int(np.sum(np.abs(steps - 2 * math.pi) < 0.5)) if smooth else 0
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
