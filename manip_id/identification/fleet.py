"""Fleet scale: identification over many logs, accumulated on Dask and solved on the client.

Least squares over a fleet of logs is a map-reduce, because the information
sums of disjoint data add (:class:`~manip_id.estimators.InformationAccumulator`
is a monoid). For files ``f`` cut into blocks ``b`` (each one task), per joint ``j``::

    A_j  = sum_f sum_b  Y_fbj^T Y_fbj        (r, r)    on the workers
    b_j  = sum_f sum_b  Y_fbj^T tau_fbj      (r,)
    zz_j = sum_f sum_b  tau_fbj^T tau_fbj
    theta_b = solve(sum_j A_j, sum_j b_j)              on the client

It is the file path of the one door, :func:`manip_id.identification.identify` with a
``RunOptions(scheduler=...)`` or ``FileOptions(partition=PartitionOptions(...))``. Each
task is the real-log pipeline's unit of work
(:func:`manip_id.identification.accumulate_file`, the tasks of
:mod:`manip_id.identification.tasks`): it reads its file in chunks,
checks it against the robot, preprocesses it in overlapping blocks when the file
lacks ``ddq`` or filtering is asked for, and accumulates the base-regressor
rows. A block of a long file (``block`` samples of the preprocessed stream) is
a task of its own that accumulates only its rows of that same stream, so the
partition changes the sums only by round-off. The parts are added in a tree
(``split_every`` at a time: blocks into files, files into the fleet), always in
the same grouping. The client receives ``nv`` matrices of ``r x r`` (and one
set per file with ``per_file``), never samples.

Weighted least squares needs no second pass: the per-joint residual sums at an
estimate are linear in the sums, ``RSS_j(theta) = sum_tasks (zz_j - 2 b_j.theta +
theta.A_j.theta)``, i.e. the sum of the per-task residual sums, so the variances
``sigma_j^2 = RSS_j / (n - r / nv)`` and the re-weighted solve come from the
reduced sums alone, exactly as in the local run. Validation files are tasks too;
their errors for the estimate follow from their sums in the same way.

Back-ends: no scheduler runs the same tasks and the same tree in this process
(and imports nothing of Dask); ``"local"`` / ``"local:N"`` starts a
``LocalCluster`` of N single-threaded worker processes on 127.0.0.1 (stopped at
the end); ``"tcp://HOST:PORT"`` connects to a running scheduler; a path to a
scheduler JSON file (``dask scheduler --scheduler-file``) too; a
``distributed.Client`` is used as it is. A worker that dies mid-run has its
tasks recomputed by Dask elsewhere; a bad file fails the run with a
:class:`~manip_id.errors.DataError` naming the file, and no result.
"""

from __future__ import annotations

from ..execution import (
    DEFAULT_LOCAL_WORKERS,
    SPLIT_EVERY,
    WORKER_ENV,
    parse_scheduler,
    portable_robot,
)
from . import LEAST_SQUARES, FileEstimate, PartitionOptions
from .tasks import FilePart, PartSums, file_length, part_sums

#: Methods that accumulate (the online laws need the samples in order).
FLEET_METHODS: tuple[str, ...] = LEAST_SQUARES

__all__ = [
    "DEFAULT_LOCAL_WORKERS",
    "FLEET_METHODS",
    "SPLIT_EVERY",
    "WORKER_ENV",
    "FileEstimate",
    "FilePart",
    "PartSums",
    "PartitionOptions",
    "file_length",
    "parse_scheduler",
    "part_sums",
    "portable_robot",
]
