"""The data side of the ``temperature`` friction law: its reference T0 and its range.

The law (:mod:`manip_id.robot.friction`) adds the columns ``(T_j - T0_j) dq_j`` and ``(T_j - T0_j)
sign(dq_j)``; ``T0`` is a shape, fixed before any sum is accumulated, so that sums of parts
(files, forked processes, Dask tasks) add up to the sums of the whole. It is the mean
temperature per DoF of the training data *as read* (the rows the fit reads, before the
preprocessing's trim and filter), with the range ``[T_min, T_max]`` it spans, from
:class:`~manip_id.robot.friction.TemperatureStats` summed over the files' scans (or over the
arrays of an in-memory fit)::

    T0_j = sum_k T_kj / N            T_min,j = min_k T_kj     T_max,j = max_k T_kj

A reference given beforehand (``FrictionShapes(temperature_reference=...)``) is kept. The
range is kept as the shapes' ``temperature_low``, ``temperature_high``: the physically
consistent estimate keeps ``fv + fvt (T - T0) >= 0`` and ``fc + fct (T - T0) >= 0`` at
both ends (:func:`~manip_id.estimators.consistent.problem.temperature_rows`).
Centring keeps ``fv`` and ``fc`` the coefficients at the data's mean temperature (well
conditioned: the raw ``T dq`` column is nearly collinear with ``dq`` when T is in K).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import MissingTemperatureError
from ..robot.friction import NO_SHAPES, TemperatureStats
from ..robot.model import Robot
from .reading import open_checked, scan_file
from .tasks import file_specs


def check_scans_temperature(robot: Robot, scans) -> None:
    """Raise :class:`~manip_id.errors.MissingTemperatureError` when ``robot`` models the
    temperature law and one of ``scans`` (:class:`~.reading.FileScan`) has no temp field."""
    if not robot.layout.needs_temperature:
        return
    for scan in scans:
        if scan.temperature is None:
            raise MissingTemperatureError(scan.spec.label, scan.format, scan.layout.fields)


def check_sources_temperature(robot: Robot, specs) -> None:
    """:func:`check_scans_temperature` before any row is read: each file of ``specs``
    (:class:`~manip_id.datasets.FileSpec`) opened for its fields only, so that a missing
    temperature is said before the audit and the scans run."""
    if not robot.layout.needs_temperature:
        return
    for spec in specs:
        src, _ = open_checked(robot, spec)
        if "temp" not in src.layout.fields:
            raise MissingTemperatureError(spec.label, src.format, src.layout.fields)


def scans_temperature(scans) -> TemperatureStats | None:
    """The temperature sums of ``scans`` added (None: no scan has a temperature)."""
    total = None
    for scan in scans:
        if scan.temperature is not None:
            total = scan.temperature if total is None else total + scan.temperature
    return total


def with_temperature_reference(
    robot: Robot, stats: TemperatureStats | None, *, modelled: bool = True
) -> Robot:
    """``robot`` with ``T0`` the mean of ``stats`` per DoF (module docstring) when it has
    none and models the temperature law (``modelled=False``: whatever its laws, for the
    candidates of a model selection); else ``robot`` itself."""
    shapes = robot.layout.shapes or NO_SHAPES
    if stats is None or shapes.temperature_reference is not None:
        return robot
    if modelled and not robot.layout.needs_temperature:
        return robot
    mean, low, high = (tuple(map(float, v)) for v in stats.per_dof(robot.nv))
    shapes = replace(shapes, temperature_reference=mean, temperature_low=low, temperature_high=high)
    return robot.with_terms(replace(robot.terms, shapes=shapes))


def reference_from_scans(robot: Robot, scans) -> Robot:
    """The training ``scans`` checked for a temp field, and ``T0`` from their sums."""
    scans = list(scans)
    check_scans_temperature(robot, scans)
    return with_temperature_reference(robot, scans_temperature(scans))


def reference_from_files(robot: Robot, files, validation, options, window=None, scans=None):
    """``(robot, scans, made)``: with the temperature law, every file (specs or texts;
    ``window`` for those without one) scanned unless in ``scans`` (``made``: the scans
    made here, to discard), checked for a temp field, and ``T0`` from the training scans;
    else the arguments as they came."""
    scans = dict(scans or {})
    if not robot.layout.needs_temperature:
        return robot, scans, []
    specs = file_specs(files, "paths", window)
    vspecs = [] if validation is None else file_specs(validation, "validation", window)
    made = []
    for s in specs + vspecs:
        if s not in scans:
            scans[s] = scan_file(robot, s, options)
            made.append(scans[s])
    check_scans_temperature(robot, [scans[s] for s in vspecs])
    return reference_from_scans(robot, [scans[s] for s in specs]), scans, made


def candidate_reference(robot: Robot, specs, vspecs, scans: dict) -> Robot | None:
    """``robot`` with ``T0`` (whatever its laws, for the candidates of a model selection)
    when every file's scan in ``scans`` (training ``specs`` and validation ``vspecs``) has a
    temperature, else None."""
    found = [scans.get(s) for s in list(specs) + list(vspecs or [])]
    if not found or any(s is None or s.temperature is None for s in found):
        return None
    return with_temperature_reference(robot, scans_temperature(found[: len(specs)]), modelled=False)


def reference_from_arrays(robot: Robot, temp) -> Robot:
    """``T0`` from the in-memory temperatures ``temp`` (N, nv) or (N, 1) of a fit; refuses
    a missing ``temp`` when the robot models the law."""
    if not robot.layout.needs_temperature:
        return robot
    if temp is None:
        raise MissingTemperatureError("the arrays", "arrays", ("q", "dq", "ddq", "tau"))
    return with_temperature_reference(robot, TemperatureStats.of(np.atleast_1d(temp)))


def note_reference(result, robot: Robot):
    """``result`` with ``context["friction_shapes"]`` the shapes of ``robot`` (its ``T0``)
    when it models the temperature law (the reference its ``fvt``, ``fct`` refer to)."""
    if robot.layout.needs_temperature:
        result.context["friction_shapes"] = (robot.layout.shapes or NO_SHAPES).to_dict()
    return result


def reference_text(robot: Robot) -> str | None:
    """One line naming the temperature law's ``T0`` and range per DoF, or None."""
    shapes = robot.layout.shapes or NO_SHAPES
    if not robot.layout.needs_temperature or shapes.temperature_reference is None:
        return None
    cells = []
    for j, dof in enumerate(robot.dof_names):
        cell = f"{dof} {shapes.temperature_reference[j]:.4g}"
        if shapes.temperature_low is not None and shapes.temperature_high is not None:
            cell += f" ({shapes.temperature_low[j]:.4g} to {shapes.temperature_high[j]:.4g})"
        cells.append(cell)
    return "temperature law: T0 (training mean, range) per joint: " + ", ".join(cells)


__all__ = [
    "candidate_reference",
    "check_scans_temperature",
    "check_sources_temperature",
    "note_reference",
    "reference_from_arrays",
    "reference_from_files",
    "reference_from_scans",
    "reference_text",
    "scans_temperature",
    "with_temperature_reference",
]
