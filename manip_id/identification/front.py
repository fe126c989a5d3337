"""The one door: ``identify(robot, data) = solve(build_problem(robot, data))``.

For N samples ``(q, dq, ddq, tau)`` in any form (:mod:`~.data_sources`: arrays, a
:class:`~manip_id.datasets.Dataset`, log files, blocks, parts)::

    build_problem     checks, (files: audit, scans, temperature reference, friction choice),
                      base parameters, the sums A_j = sum Y_j^T Y_j, b_j = sum Y_j^T tau_j
    solve             rank check, least squares (or the online law's estimate), errors,
                      the run's context and post-steps -> IdentificationResult

Python users and ``manip-id identify`` go through the same two calls, so a Python user
gets what the command line prints: the audit, the automatic choices, the per-file records.
"""

from __future__ import annotations

from ..errors import InputError
from ..identifiability import BaseParameters
from ..robot.model import Robot
from .arrays import CallOptions, blocks_problem, samples_problem
from .data_sources import Blocks, Files, Samples, data_source
from .file_run import FileOptions, files_build
from .options import (
    ConsistentOptions,
    ModelOptions,
    OnlineOptions,
    RunOptions,
    SolveSettings,
    UncertaintyOptions,
    check_method,
)
from .problem import Problem
from .result import IdentificationResult
from .solve import solve


def build_problem(
    robot: Robot,
    data,
    *,
    validation=None,
    method: str = "wls",
    base: BaseParameters | None = None,
    consistent: ConsistentOptions | bool | dict | None = None,
    minimum_norm: bool = False,
    model: ModelOptions | str | dict | None = None,
    online: OnlineOptions | dict | None = None,
    run: RunOptions | dict | None = None,
    uncertainty: UncertaintyOptions | str | dict | None = None,
    files: FileOptions | None = None,
) -> Problem:
    """The accumulated problem of ``data``, ready for :func:`solve` (arguments as
    :func:`identify`)."""
    if not isinstance(robot, Robot):
        raise InputError(f"robot must be a Robot (manip_id.load_robot), got {type(robot).__name__}")
    check_method(method)
    if files is not None and not isinstance(files, FileOptions):
        raise InputError(f"files must be FileOptions or None, got {type(files).__name__}")
    settings = SolveSettings(
        method,
        ConsistentOptions.from_value(consistent),
        bool(minimum_norm),
        UncertaintyOptions.from_value(uncertainty),
    )
    opts = CallOptions(
        ModelOptions.from_value(model), OnlineOptions.from_value(online), RunOptions.from_value(run)
    )
    source = data_source(data)
    if files is not None and not isinstance(source, Files):
        raise InputError(f"files= applies to log files; data is {type(source).__name__.lower()}")
    if isinstance(source, Files):
        vfiles = None
        if validation is not None:
            vsource = data_source(validation, "validation")
            if not isinstance(vsource, Files):
                raise InputError(
                    f"with log files as data, validation must be files too, got "
                    f"{type(vsource).__name__.lower()}"
                )
            vfiles = vsource.specs
        fopts = files or FileOptions()
        return files_build(robot, source.specs, vfiles, base, settings, opts, fopts)
    if isinstance(source, Samples):
        return samples_problem(robot, source, _validation_arrays(validation), base, settings, opts)
    if opts.model.name != "dynamic":
        raise InputError(f"the {opts.model.name} model takes arrays, a Dataset or files")
    vblocks = None
    if validation is not None:
        vsource = data_source(validation, "validation")
        vblocks = [vsource.arrays()] if isinstance(vsource, Samples) else _blocks_of(vsource)
    problem = blocks_problem(robot, source, vblocks, base, settings, opts.run)
    return problem


def _validation_arrays(validation) -> tuple | None:
    """``validation`` of in-memory data as ``(q, dq, ddq, tau[, temp])``, or None."""
    if validation is None:
        return None
    v = data_source(validation, "validation")
    if not isinstance(v, Samples):
        raise InputError(
            f"with arrays or a Dataset as data, validation must be arrays or a Dataset too, "
            f"got {type(v).__name__.lower()}"
        )
    if v.ddq is None:
        raise InputError("the validation data have no accelerations (ddq)")
    return v.arrays()


def _blocks_of(source):
    if isinstance(source, Blocks):
        return source.blocks
    raise InputError(
        f"with blocks as data, validation must be arrays or blocks, got {type(source).__name__}"
    )


def identify(
    robot: Robot,
    data,
    *,
    validation=None,
    method: str = "wls",
    base: BaseParameters | None = None,
    consistent: ConsistentOptions | bool | dict | None = None,
    minimum_norm: bool = False,
    model: ModelOptions | str | dict | None = None,
    online: OnlineOptions | dict | None = None,
    run: RunOptions | dict | None = None,
    uncertainty: UncertaintyOptions | str | dict | None = None,
    files: FileOptions | None = None,
) -> IdentificationResult:
    """Identify the base parameters of ``robot`` from ``data``, streamed.

    ``solve(build_problem(robot, data, ...))``: one door for every kind of data.

    Parameters
    ----------
    robot : Robot
        The robot (its joint terms decide the columns).
    data
        N samples, as any of (:func:`~manip_id.identification.data_sources.data_source`):

        - arrays ``(q, dq, ddq, tau[, temp])``: positions [rad or m], shape (N, nq);
          velocities [rad/s], accelerations [rad/s^2] and torques [N m], shape (N, nv);
          ``ddq`` may be None for the energy and momentum models; ``temp`` [deg C], (N, nv)
          or (N, 1), the temperature of the ``temperature`` friction law;
        - a :class:`~manip_id.datasets.Dataset` (its ``temp`` too; its mean sample time is
          the energy / momentum models' ``dt`` unless given);
        - log files: a path, ``PATH@START:STOP`` [s], ``PATH@#A:#B`` [rows], a
          :class:`~manip_id.datasets.FileSpec`, or a list of them (NPZ, CSV, ROS 2 bags,
          Panda log folders): audited, scanned and preprocessed each on its own
          (:mod:`~manip_id.identification.file_run`, options ``files``);
        - an iterable of blocks ``(q, dq, ddq, tau)``, accumulated in order, or a list of
          parts ``(func, args)``, each in a forked process or a Dask task (least squares).
    validation
        Data for the validation error, of the same kind (arrays or a Dataset with arrays,
        files with files, blocks with blocks).
    method : str
        "wls" (default: weighted by per-joint noise variances from the OLS residuals,
        re-estimated from the weighted ones), "ols" (ordinary least squares), "rls" or
        "gradient" (one pass of the online law, in sample order; arrays and files).
    base : BaseParameters or None
        Base parametrization; default the structural one of ``analyze(robot)``.
    consistent : ConsistentOptions, bool or None
        Physically consistent standard parameters ("ols"/"wls"); True: the defaults.
    minimum_norm : bool
        Solve rank-deficient data with the minimum-norm solution instead of raising
        :class:`~manip_id.errors.RankDeficiencyError`.
    model : ModelOptions, str or None
        "dynamic" (default, needs ``ddq``), "energy" or "momentum", with the window
        length and the sample time ``dt`` [s].
    online : OnlineOptions or dict or None
        Options of the online law.
    run : RunOptions or None
        ``chunk``, ``workers`` (forked processes, equal to the serial result to
        round-off), ``scheduler`` (Dask: files or parts as tasks), ``progress(done,
        total)``, ``echo(text)`` (what a file run finds, as it finds it).
    uncertainty : UncertaintyOptions, str, dict or None
        The covariance behind ``std``: "auto" (default), "white" or "hac"
        (:mod:`manip_id.estimators.uncertainty`).
    files : FileOptions or None
        How log files are read: preprocessing, window, pre-fit audit, standstill trim,
        split, partition into tasks (per-file estimates), the friction law chosen per joint.

    Returns
    -------
    IdentificationResult
        Its ``to_dict()`` is the JSON of ``manip-id identify --json``: for files with the
        audit, the data quality and records of each file, the source and preprocessing.
    """
    problem = build_problem(
        robot, data, validation=validation, method=method, base=base, consistent=consistent,
        minimum_norm=minimum_norm, model=model, online=online, run=run,
        uncertainty=uncertainty, files=files,
    )  # fmt: skip
    return solve(problem)


__all__ = ["FileOptions", "build_problem", "identify"]
