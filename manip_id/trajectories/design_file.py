"""A design file (``manip-id excite --json``) read back: the trajectory and its duration.

Read at its door, every field checked (:class:`~manip_id._io.fields.Fields`) before
:func:`manip_id.simulation.simulate` runs along it (``manip-id simulate --trajectory``).
"""

from __future__ import annotations

import math

import numpy as np

from .._checks import MEASURED_LIMITS
from .._io.fields import Fields
from .._io.reading import read_json
from ..errors import InputError
from ..robot.model import Robot, available_robots
from .fourier import FourierTrajectory

#: The largest magnitude of a design's Fourier coefficients [rad or m] (the plausible
#: positions of :data:`manip_id._checks.MEASURED_LIMITS`).
MAX_COEFFICIENT = MEASURED_LIMITS["q"][1]


def read_design(path, robot: Robot | None = None) -> tuple[FourierTrajectory, float]:
    """The trajectory and duration [s] of a design JSON (``manip-id excite --json``).

    Every field is checked at the door (:class:`~manip_id._io.fields.Fields`): the
    coefficients ``q0`` (nv,), ``a`` and ``b`` (nv, L) finite and within
    :data:`MAX_COEFFICIENT`, ``wf`` [rad/s] positive with its highest harmonic below the
    Nyquist pulsation of the design's ``rate`` (when it says), ``duration`` [s] positive;
    with ``robot``, the design's robot and joints must be its own. One
    :class:`InputError` names the file, the field and what came.
    """
    doc = read_json(path, "design", error=InputError)
    f = Fields(path, error=InputError)
    exc = f.object(f.object(doc, "the design").get("excitation"), "excitation")
    c = f.object(exc.get("coefficients"), "excitation.coefficients")
    q0 = f.list(c.get("q0"), "excitation.coefficients.q0", nonempty=True)
    nv = len(q0)
    a = f.list(c.get("a"), "excitation.coefficients.a", nonempty=True)
    first = f.list(a[0], "excitation.coefficients.a[0]", nonempty=True)
    shape = (nv, len(first))
    arrays = {
        "q0": np.array([f.number(v, f"excitation.coefficients.q0[{k}]") for k, v in enumerate(q0)]),
        "a": f.matrix(a, "excitation.coefficients.a", shape),
        "b": f.matrix(c.get("b"), "excitation.coefficients.b", shape),
    }
    for name, arr in arrays.items():
        if np.abs(arr).max() > MAX_COEFFICIENT:
            raise f.fail(
                f"excitation.coefficients.{name}",
                f"coefficients of magnitude <= {MAX_COEFFICIENT:g} [rad or m]",
                float(np.abs(arr).max()),
            )
    wf = f.number(c.get("wf"), "excitation.coefficients.wf", positive=True)
    duration = f.number(exc.get("duration"), "excitation.duration", positive=True)
    rate = exc.get("rate")
    if rate is not None:
        rate = f.number(rate, "excitation.rate", positive=True)
        if wf * shape[1] >= math.pi * rate:
            raise f.fail(
                "excitation.coefficients.wf",
                f"a pulsation whose {shape[1]} harmonics stay below the Nyquist pulsation "
                f"pi * rate = {math.pi * rate:g} rad/s",
                wf,
            )
    if robot is not None:
        name = doc.get("robot")
        known = set(available_robots())  # two robots known by name: another robot's design
        if name is not None and f.text(name, "robot") != robot.name and {name, robot.name} <= known:
            raise InputError(f"{path} is a design for robot {name!r}, not for {robot.name!r}")
        if nv != robot.nv:
            raise InputError(f"{path} designs {nv} joints but {robot.name!r} has {robot.nv}")
    traj = FourierTrajectory(arrays["q0"], arrays["a"], arrays["b"], wf)
    return traj, duration


__all__ = ["MAX_COEFFICIENT", "read_design"]
