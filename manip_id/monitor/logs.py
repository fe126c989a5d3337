"""Logs for the monitor: files read as the identification pipeline reads them, unfiltered.

An online observer sees the raw signals, so a file is read with the pipeline's readers
(any format, a window ``FILE@START:STOP``, a torque scale, dropped bad rows, a CSV column
map, a ROS bag topic) but not filtered or differentiated: ``t`` (the file's own time
[s]), ``q``, ``dq``, ``tau`` as logged (``ddq`` when the file has it, ``temp`` the joints'
temperature when it holds a temp field: the ``temperature`` friction law needs it, as
identify does; a log without one is refused for that law with
:class:`~manip_id.errors.MissingTemperatureError`).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..datasets import Dataset, FileSpec, check_robot, iter_rows, open_source, parse_file_spec
from ..datasets.stream import RowCounts, collect, infer_format, torque_scale_vector
from ..errors import DataError, InputError, MissingTemperatureError
from ..robot.model import Robot


@dataclass(frozen=True)
class MonitorLog:
    """One log: ``t`` (N,) [s], ``q`` (N, nq), ``dq``, ``tau`` (N, nv), ``ddq`` or None,
    ``file`` its label, ``n_dropped`` rows left out for NaN/Inf, ``temp`` the joints'
    temperature [degC or K], (N, nv) or (N, 1), or None; ``format`` and ``fields`` what the
    file was (for the message of a missing temperature)."""

    file: str
    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    tau: np.ndarray
    ddq: np.ndarray | None = None
    n_dropped: int = 0
    temp: np.ndarray | None = None
    format: str = "arrays"
    fields: tuple[str, ...] = ("t", "q", "dq", "tau")

    @property
    def n_samples(self) -> int:
        """Number of samples N."""
        return int(self.t.size)


@dataclass(frozen=True)
class ReadOptions:
    """How files are read (the identify command's file options).

    torque_scale: one gain or one per joint: ``tau_j <- G_j tau_j`` (None: 1)
    drop_bad_rows: drop (and count) rows holding NaN/Inf instead of refusing the file
    window: a window for files given without one (``"START:STOP"`` [s] or ``"#A:#B"``)
    columns: column map of the CSV files (other formats ignore it); topic: ROS bag topic
        (of the bags)
    """

    torque_scale: float | tuple[float, ...] | None = None
    drop_bad_rows: bool = False
    window: str | None = None
    columns: Mapping | None = None
    topic: str | None = None


def read_log(robot: Robot, spec, options: ReadOptions | None = None) -> MonitorLog:
    """Read one file (a path, ``PATH@START:STOP`` or a :class:`~manip_id.datasets.FileSpec`).

    Raises :class:`~manip_id.errors.DataError` naming the file when it cannot be read or
    does not fit the robot.
    """
    options = options or ReadOptions()
    spec = parse_file_spec(spec, window=options.window)
    if robot.transmission is not None and not spec.transmission:  # motor-side logs converted
        spec = replace(spec, transmission=robot.transmission)
    fmt = spec.format or (infer_format(spec.path) if spec.path.exists() else None)
    if fmt == "csv" and options.columns is not None:  # the column map is for CSV files
        spec = FileSpec(spec.path, spec.window, spec.format, options.columns, spec.topic)
    if fmt == "rosbag" and options.topic is not None:  # the topic is for ROS bags
        spec = FileSpec(spec.path, spec.window, spec.format, spec.columns, options.topic)
    src = open_source(spec, joint_names=list(robot.dof_names))
    scale = torque_scale_vector(options.torque_scale, src.layout.nv, "the torque scale")
    counts = RowCounts()
    try:
        rows = iter_rows(
            src,
            spec.window,
            torque_scale=scale,
            drop_bad_rows=options.drop_bad_rows,
            counts=counts,
        )
        ds = collect(rows, src.layout, src.joint_names)
        check_robot(ds, robot)
    except (DataError, InputError) as exc:
        msg = str(exc)
        raise DataError(msg if str(spec.path) in msg else f"{spec.label}: {msg}") from exc
    if ds.t.size < 2:
        raise DataError(f"{spec.label}: {ds.t.size} usable sample(s); need at least 2")
    fields = tuple(src.layout.fields)
    return MonitorLog(
        spec.label, ds.t, ds.q, ds.dq, ds.tau, ds.ddq, counts.n_dropped, ds.temp, src.format, fields
    )


def as_logs(robot: Robot, data, options: ReadOptions | None = None) -> list[MonitorLog]:
    """Logs from files, :class:`MonitorLog` s, datasets or ``{"t", "q", "dq", "tau"}``
    mappings (with ``"ddq"`` and ``"temp"`` when they have them), one or a sequence."""
    single = isinstance(data, str | os.PathLike | FileSpec | MonitorLog | Dataset | Mapping)
    items: Sequence = [data] if single else list(data)
    if not items:
        raise InputError("no logs given")
    out = []
    for i, item in enumerate(items):
        if isinstance(item, MonitorLog):
            out.append(item)
        elif isinstance(item, Dataset):
            check_robot(item, robot)
            out.append(
                MonitorLog(
                    f"dataset {i}", item.t, item.q, item.dq, item.tau, item.ddq, temp=item.temp
                )
            )
        elif isinstance(item, Mapping):
            missing = [k for k in ("t", "q", "dq", "tau") if k not in item]
            if missing:
                raise InputError(f"log {i} misses {missing} (expected keys t, q, dq, tau)")
            arr = {k: np.asarray(item[k], dtype=float) for k in ("t", "q", "dq", "tau")}
            ddq, temp = item.get("ddq"), item.get("temp")
            out.append(
                MonitorLog(
                    file=str(item.get("file", f"log {i}")),
                    t=arr["t"],
                    q=arr["q"],
                    dq=arr["dq"],
                    tau=arr["tau"],
                    ddq=None if ddq is None else np.asarray(ddq, dtype=float),
                    temp=None if temp is None else np.asarray(temp, dtype=float),
                )
            )
        else:
            out.append(read_log(robot, item, options))
    return out


def check_temperatures(logs: Sequence[MonitorLog], needed: bool) -> None:
    """When the model needs the temperature (``needed``), every log must carry one:
    :class:`~manip_id.errors.MissingTemperatureError` naming the first that does not
    (before any work)."""
    if not needed:
        return
    for lg in logs:
        if lg.temp is None:
            raise MissingTemperatureError(lg.file, lg.format, lg.fields)
