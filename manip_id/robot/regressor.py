"""Regressors: Y(q, dq, ddq) and the Slotine-Li Y(q, dq, v, w), with joint-level terms.

Inverse dynamics is linear in the parameters of :class:`~manip_id.robot.model.Robot`::

    tau = M(q) ddq + C(q, dq) dq + g(q) + joint terms = Y(q, dq, ddq) theta

The rigid-body columns come from ``pinocchio.computeJointTorqueRegressor``; the
joint-term columns (only row ``j`` is non-zero for the terms of joint ``j``) are

    Ia: ddq_j    fv: dq_j    fc: sign(dq_j)    fo: 1    k: q_j    ... (parameters.JOINT_TERMS)

(``q_j`` is the joint angle; for a continuous joint stored as (cos, sin) it is
``atan2(sin, cos)``). The ``temperature`` law's columns also take the measured
temperature ``temp``, shape (nv,) / (N, nv), or one column (1,) / (N, 1) broadcast to every
joint, or a scalar [degC or K]: the keyword ``temp`` of the functions below.

Slotine-Li form. ``Y(q, dq, v, w) theta = M(q) v + C(q, dq) w + g(q)`` with the
Christoffel-consistent C. Its velocity part is the symmetric bilinear form
``Q(dq, w) = C(q, dq) w = C(q, w) dq`` with ``Q(x, x) = C(q, x) x``, so with
``a = (dq + w)/2`` and ``b = (dq - w)/2`` the polarization identity gives it
from two regressor calls, exactly::

    Y(q, dq, v, w) = Y_rnea(q, a, v) - Y_rnea^{g=0}(q, b, 0)

because ``Q(a, a) - Q(b, b) = Q(dq, w)``. The joint terms take ``v`` as the
acceleration and ``w`` as the velocity: ``Ia: v_j, fv: w_j, fc: sign(w_j),
fo: 1, k: q_j``. Hence ``Y(q, dq, ddq, dq) == Y(q, dq, ddq)``.

Stacking is sample-major: a batch is returned as shape (N, nv, p), whose
``reshape(N * nv, p)`` has row ``k*nv + j`` for joint ``j`` of sample ``k``.
Over long trajectories use :func:`iter_regressor`, which evaluates chunk by
chunk into one preallocated buffer.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from .._checks import as_float_array, check_finite
from .._numba import numba_warm
from ..errors import InputError
from ..resources import check_regressor_buffer
from .compiled_regressor import (
    AUTO_SAMPLES,
    CompiledModel,
    compile_model,
    count_samples,
    mode,
    planned,
    rigid_block,
)
from .friction import HysteresisCarry, hysteresis_state

if TYPE_CHECKING:
    from .model import Robot

DEFAULT_CHUNK = 1024
_STACK = 32


@dataclass(frozen=True)
class RegressorChunk:
    """A block of a stacked regressor.

    ``Y`` has shape (stop - start, nv, p) and covers samples ``start:stop``.
    It is a view of a buffer reused for the next chunk: copy it to keep it.
    """

    start: int
    stop: int
    Y: np.ndarray


class RegressorEvaluator:
    """Preallocated evaluation of the regressors of one robot (for hot loops).

    The methods assume float64 arrays of the right shapes (the public
    functions of this module check them); they are what online estimators and
    the adaptive controller call at every step.
    """

    def __init__(self, robot: Robot):
        self.robot = robot
        self.model = robot.model
        self.data = robot.model.createData()
        self.model0 = robot.gravity_free_model
        self.data0 = self.model0.createData()
        self.nv = robot.nv
        self.nq = robot.nq
        self.p = robot.n_parameters
        self.n_rigid = robot.n_rigid
        self.layout = robot.layout
        self.terms = robot.terms.enabled
        nt = len(self.terms)
        self._rows = np.repeat(np.arange(self.nv), nt)
        self._cols = self.n_rigid + np.arange(self.nv * nt)
        self._dofs = robot.dofs
        self._zero = np.zeros(self.nv)
        # flat indices into a (nv, p) block of the diagonal entries of each term
        rows = np.arange(self.nv) * self.p
        self._flat = [(t, rows + self.layout.joint_columns(t.name)) for t in self.layout.term_table]
        tr = robot.transmission
        self.motors = tr if tr is not None and tr.n_parameters else None  # motor-term columns
        self.motor_start = self.n_rigid + nt * self.nv  # [-] (p: no motor terms)
        self._needs_angles = any(t.needs_angles for t in self.layout.term_table)
        self._load_model = robot.load_model  # the load law's rnea: the nominal inertias
        self._load_data = self._load_model.createData()
        self._compiled: CompiledModel | None | bool = False  # False: not looked up yet
        self._seen = 0  # samples evaluated in blocks [-]
        self._carry: HysteresisCarry | None = None  # the hysteresis state between blocks
        self._depth = 0  # open trajectories (:meth:`sequence`)
        #: Whether a term is a state of the samples' path (the ``hysteresis`` law).
        self.needs_history = any(t.needs == "history" for t in self.layout.term_table)

    # ------------------------------------------------------------ rigid blocks
    @property
    def compiled(self) -> CompiledModel | None:
        """The compiled block kernel's model, or None (Pinocchio per sample)."""
        if self._compiled is False:
            self._compiled = compile_model(self.model)
        return self._compiled  # type: ignore[return-value]

    def kernel_for(self, n: int) -> CompiledModel | None:
        """The compiled kernel for a block of ``n`` samples, or None for Pinocchio.

        Mode ``compiled``: whenever the model is covered; ``auto``: for a run announced
        with at least :data:`~manip_id.robot.compiled_regressor.AUTO_SAMPLES` samples
        (:func:`~manip_id.robot.compiled_regressor.planned_samples`), and outside any announced
        run once this process has seen that many samples or once a numba kernel has run
        in it (the filter of the log preprocessing: :func:`~manip_id._numba.numba_warm`);
        ``pinocchio``: never (see :mod:`manip_id.robot.compiled_regressor`). An announced run is
        decided by its size alone, so every process of it (this one, forked workers, Dask
        workers, whatever they evaluated before) takes the same path and gives the same
        round-off.
        """
        self._seen += n
        current = mode()
        seen, announced = count_samples(n), planned()
        large = announced >= AUTO_SAMPLES if announced > 0 else seen >= AUTO_SAMPLES or numba_warm()
        if current == "pinocchio" or (current == "auto" and not large):
            return None
        return self.compiled

    def rigid_block(self, q, dq, ddq, out: np.ndarray, gravity: bool = True) -> None:
        """Y_rigid for a block of samples into ``out`` (N, nv, n_rigid), in place.

        The compiled kernel when :meth:`kernel_for` says so, else one Pinocchio call per
        sample (``gravity=False``: the gravity-free model of the Slotine-Li velocity part).
        """
        desc = self.kernel_for(q.shape[0])
        if desc is not None:
            rigid_block(desc, q, dq, ddq, out, gravity=gravity)
            return
        f = pin.computeJointTorqueRegressor
        m, d = (self.model, self.data) if gravity else (self.model0, self.data0)
        for k in range(q.shape[0]):
            out[k] = f(m, d, q[k], dq[k], ddq[k])

    # ------------------------------------------------- hysteresis: a path state
    @contextmanager
    def sequence(self):
        """One trajectory over several calls: the hysteresis state (the ``fh`` column,
        :func:`~manip_id.robot.friction.hysteresis_state`) carries from each block to the next.

        Entering starts a trajectory (state 0 before its first sample); a nested entry
        joins the open one. Outside, each call's samples are a trajectory of their own.
        """
        if self._depth == 0:
            self._carry = None
        self._depth += 1
        try:
            yield self
        finally:
            self._depth -= 1
            if self._depth == 0:
                self._carry = None

    def sequential(self, blocks) -> Iterator:
        """``blocks`` as they come, within one :meth:`sequence` (a stream of blocks)."""
        with self.sequence():
            yield from blocks

    def advance(self, q) -> None:
        """Run the open trajectory's hysteresis state over samples ``q`` (N, nq) that are
        not evaluated (the rows before a span of a file): the next block starts where
        the whole stream would. A no-op without the law or an open :meth:`sequence`."""
        if self.needs_history and self._depth and len(q):
            self._history(self.joint_angles(np.asarray(q, dtype=float)))

    def refuse_history(self, what: str) -> None:
        """Raise :class:`InputError` when the ``hysteresis`` law is modelled (``what``
        has no measured path to run its state over)."""
        if self.needs_history:
            raise InputError(
                f"the hysteresis friction law (fh) is a state of the measured joint path; "
                f"{what} cannot evaluate it: use the dynamic model (tau = Y(q, dq, ddq) theta)"
            )

    def _history(self, angles) -> np.ndarray:
        """The Dahl state of the samples' angles (N, nv), carried within a sequence."""
        if np.ndim(angles) < 2:
            raise InputError(
                "the hysteresis friction law (fh) is a state of the joint's path: it needs "
                "the samples in order (2-D arrays), not one sample"
            )
        trace = hysteresis_state(angles, self.layout.shapes, self._carry if self._depth else None)
        if self._depth:
            self._carry = trace.carry
        return trace.state

    # ------------------------------------------------------------ joint terms
    def joint_angles(self, q: np.ndarray) -> np.ndarray:
        """Joint coordinate per velocity DoF, shape (..., nv) [rad or m]."""
        return self._dofs.angles(q)

    def joint_values(self, q, vel, acc, temp=None) -> np.ndarray:
        """Joint-term regressor entries, shape (..., nv, n_terms) (``parameters.JOINT_TERMS``);
        ``temp`` the temperature, shape like ``vel`` (the ``temperature`` law)."""
        angles = self.joint_angles(q) if self._needs_angles else None
        load = self.load_torque(q, vel, acc) if self.layout.needs_load else None
        history = self._history(angles) if self.needs_history else None
        return self.layout.joint_values(angles, vel, acc, load, temp, history)

    def load_torque(self, q, vel, acc) -> np.ndarray:
        """The nominal rigid-body torque ``rnea(q, vel, acc)`` of :attr:`Robot.load_model`
        (the URDF inertias, or those an identified robot's sidecar records), shape like
        ``vel`` (..., nv) [N m or N]: the load of the ``load`` law."""
        m, d = self._load_model, self._load_data
        if np.ndim(vel) == 1:
            return np.array(pin.rnea(m, d, q, vel, acc))
        return np.array([pin.rnea(m, d, a, b, c) for a, b, c in zip(q, vel, acc, strict=True)])

    def refuse_load(self, what: str) -> None:
        """Raise :class:`InputError` when the ``load`` law is modelled (``what`` cannot
        evaluate it: it needs the measured acceleration), or the ``hysteresis`` law (a
        state of the measured path, which ``what`` does not have)."""
        self.refuse_history(what)
        if self.layout.needs_load:
            raise InputError(
                f"the load friction law (fl) needs the measured acceleration; {what} cannot "
                "evaluate it: use the dynamic model (tau = Y(q, dq, ddq) theta)"
            )

    def refuse_temperature(self, what: str) -> None:
        """Raise :class:`InputError` when the ``temperature`` law is modelled (``what``
        carries no temperature)."""
        if self.layout.needs_temperature:
            raise InputError(
                "the temperature friction law (fvt, fct) needs the measured temperature, "
                f"which {what} cannot take: use the dynamic model (tau = Y(q, dq, ddq) theta)"
            )

    def fill_joint_terms(self, Y: np.ndarray, q, vel, acc, temp=None) -> None:
        """Write the joint-term columns of ``Y`` (nv, p) or (N, nv, p) in place.

        ``vel`` is the velocity the friction terms see and ``acc`` the acceleration
        of the armature (``dq, ddq`` for Y(q, dq, ddq); ``w, v`` for Slotine-Li).
        """
        if self.motors is not None:  # the motor terms, mapped to the joints by R^T
            Y[..., self.motor_start :] = self.motors.columns(vel, acc)
        if not self.terms:
            return
        if Y.ndim == 2:  # one sample: a few flat writes into the diagonal entries
            flat = Y.reshape(-1)
            vals = self.joint_values(q, vel, acc, temp)  # (nv, nt): shapes, mask, load
            for i, (_, idx) in enumerate(self._flat):
                flat[idx] = vals[:, i]
            return
        vals = self.joint_values(q, vel, acc, temp)
        Y[:, self._rows, self._cols] = vals.reshape(vals.shape[0], -1)

    # ----------------------------------------------------------- one sample
    def regressor(self, q, dq, ddq, out: np.ndarray | None = None, temp=None) -> np.ndarray:
        """Y(q, dq, ddq), shape (nv, p), written into ``out`` when given."""
        if out is None:
            out = np.zeros((self.nv, self.p))
        out[:, : self.n_rigid] = pin.computeJointTorqueRegressor(self.model, self.data, q, dq, ddq)
        self.fill_joint_terms(out, q, dq, ddq, temp)
        return out

    def slotine_li(self, q, dq, v, w, out: np.ndarray | None = None) -> np.ndarray:
        """Y(q, dq, v, w), shape (nv, p), written into ``out`` when given."""
        self.refuse_load("the Slotine-Li regressor")
        self.refuse_temperature("the Slotine-Li regressor")
        if out is None:
            out = np.zeros((self.nv, self.p))
        a = 0.5 * (dq + w)
        b = 0.5 * (dq - w)
        f = pin.computeJointTorqueRegressor
        np.subtract(
            f(self.model, self.data, q, a, v),
            f(self.model0, self.data0, q, b, self._zero),
            out=out[:, : self.n_rigid],
        )
        self.fill_joint_terms(out, q, w, v)
        return out

    # -------------------------------------------------------------- batches
    def iter_regressor(self, q, dq, ddq, chunk: int, temp=None) -> Iterator[RegressorChunk]:
        """Chunks of Y over a trajectory (arrays already checked; ``temp`` like ``dq``)."""
        n = q.shape[0]
        buf = np.zeros((min(chunk, max(n, 1)), self.nv, self.p))
        rigid = buf[:, :, : self.n_rigid]
        for start in self.sequential(range(0, n, chunk)):  # one path (hysteresis)
            stop = min(start + chunk, n)
            s = slice(start, stop)
            self.rigid_block(q[s], dq[s], ddq[s], rigid[: stop - start])
            Y = buf[: stop - start]
            tk = None if temp is None else temp[s]
            self.fill_joint_terms(Y, q[start:stop], dq[start:stop], ddq[start:stop], tk)
            yield RegressorChunk(start, stop, Y)

    def iter_row_supports(
        self, q, dq, ddq, columns: np.ndarray, supports: list[np.ndarray], chunk: int, temp=None
    ) -> Iterator[tuple[int, int, list[np.ndarray]]]:
        """Per joint, only the selected columns that can be non-zero in its row.

        ``columns``: sorted column indices (e.g. the base columns), length r;
        ``supports[j]``: sorted positions in ``columns`` of the entries of row
        ``j`` that are not identically zero (in a serial chain, joint ``j``'s
        torque never involves the bodies before it, nor other joints' terms).
        Yields ``(start, stop, blocks)`` with ``blocks[j]`` of shape
        (stop - start, len(supports[j])), C-contiguous: ``blocks[j][k] =
        Y(q_k, dq_k, ddq_k)[j, columns[supports[j]]]``. Buffers are reused. ``temp``: the
        temperature, shape like ``dq`` (the ``temperature`` law).
        """
        n, nv, nr = q.shape[0], self.nv, self.n_rigid
        columns = np.asarray(columns, dtype=np.intp)
        ms = self.motor_start
        motor_cols = columns[columns >= ms] - ms
        joint_cols = columns[(columns >= nr) & (columns < ms)] - nr
        owners = [self.layout.owner(nr + int(c)) for c in joint_cols]
        jc_dof = [o.index for o in owners]
        jc_term = [self.terms.index(o.parameter) for o in owners]
        # in the wide buffer, joint-term column i of ``columns`` sits at nr + i
        wide_index = np.where(columns < nr, columns, 0)
        n_extra = joint_cols.size + motor_cols.size  # joint terms, then motor terms
        wide_index[columns >= nr] = nr + np.arange(n_extra)
        selections = [wide_index[np.asarray(sj, dtype=np.intp)] for sj in supports]
        size = min(chunk, max(n, 1))
        wide = np.zeros((size, nv, nr + n_extra))
        flat = wide.reshape(size * nv, nr + n_extra)
        outs = [np.empty((size, sel.size)) for sel in selections]
        for start in self.sequential(range(0, n, chunk)):  # one path (hysteresis)
            stop = min(start + chunk, n)
            s = slice(start, stop)
            size_k = stop - start
            qs, dqs, ddqs = q[s], dq[s], ddq[s]
            desc = self.kernel_for(size_k)
            if desc is not None:
                rigid_block(desc, qs, dqs, ddqs, wide[:size_k, :, :nr])
            else:
                self._stacked_rigid(qs, dqs, ddqs, flat)
            if joint_cols.size:
                vals = self.joint_values(qs, dqs, ddqs, None if temp is None else temp[s])
                for i, (j, t) in enumerate(zip(jc_dof, jc_term, strict=True)):
                    wide[:size_k, j, nr + i] = vals[:, j, t]
            if motor_cols.size and self.motors is not None:
                mc = self.motors.columns(dqs, ddqs)
                wide[:size_k, :, nr + joint_cols.size :] = mc[:, :, motor_cols]
            blocks = []
            for j in range(nv):
                out = outs[j][:size_k]
                np.take(wide[:size_k, j], selections[j], axis=1, out=out, mode="clip")
                blocks.append(out)
            yield start, stop, blocks

    def _stacked_rigid(self, qs, dqs, ddqs, flat: np.ndarray) -> None:
        """Y_rigid by Pinocchio per sample into the rows of ``flat`` (size * nv, >= nr).

        Sample-major: the (nv, nr) matrices of consecutive samples are consecutive rows
        of ``flat``, so one concatenate per group copies them (cheaper than per joint).
        """
        nv, nr = self.nv, self.n_rigid
        f, m, d = pin.computeJointTorqueRegressor, self.model, self.data
        for i in range(0, qs.shape[0], _STACK):
            mats = [
                f(m, d, a, b, c)
                for a, b, c in zip(
                    qs[i : i + _STACK], dqs[i : i + _STACK], ddqs[i : i + _STACK], strict=True
                )
            ]
            rows = flat[i * nv : (i + len(mats)) * nv, :nr]
            if nv > 1:
                np.concatenate(mats, axis=0, out=rows)
            else:  # Pinocchio returns a 1-D row for one DoF
                np.stack(mats, axis=0, out=rows)

    def iter_slotine_li(self, q, dq, v, w, chunk: int) -> Iterator[RegressorChunk]:
        """Chunks of the Slotine-Li regressor over a trajectory (arrays already checked)."""
        self.refuse_load("the Slotine-Li regressor")
        self.refuse_temperature("the Slotine-Li regressor")
        n = q.shape[0]
        size = min(chunk, max(n, 1))
        buf = np.zeros((size, self.nv, self.p))
        rigid = buf[:, :, : self.n_rigid]
        velocity = np.empty((size, self.nv, self.n_rigid))
        zeros = np.zeros((size, self.nv))
        for start in range(0, n, chunk):
            stop = min(start + chunk, n)
            s, k = slice(start, stop), stop - start
            a = 0.5 * (dq[s] + w[s])
            b = 0.5 * (dq[s] - w[s])
            self.rigid_block(q[s], a, v[s], rigid[:k])
            self.rigid_block(q[s], b, zeros[:k], velocity[:k], gravity=False)
            rigid[:k] -= velocity[:k]
            Y = buf[: stop - start]
            self.fill_joint_terms(Y, q[start:stop], w[start:stop], v[start:stop])
            yield RegressorChunk(start, stop, Y)


# ------------------------------------------------------------------ checking
def check_states(robot: Robot, **arrays) -> tuple[bool, list[np.ndarray]]:
    """Validate state arrays: the first is positions (nq wide), the others nv wide.

    Accepts one sample (1-D arrays) or a trajectory (2-D, N rows each).
    Returns ``(batched, arrays)`` as float64 C-contiguous arrays. Errors state
    the shapes that came and the ones expected, and the sample index of a NaN/Inf.
    """
    names = list(arrays)
    out = [as_float_array(arrays[n], n, ndim=(1, 2)) for n in names]
    batched = out[0].ndim == 2
    for name, arr in zip(names, out, strict=True):
        if arr.ndim != out[0].ndim:
            raise InputError(
                f"{names[0]}.shape={out[0].shape} but {name}.shape={arr.shape}: "
                "give all states for one sample (1-D) or all for N samples (2-D)"
            )
    width = {names[0]: robot.nq, **{n: robot.nv for n in names[1:]}}
    for name, arr in zip(names, out, strict=True):
        expected = width[name]
        if arr.shape[-1] != expected:
            what = "robot.nq" if name == names[0] else "robot.nv"
            raise InputError(f"{name}.shape={arr.shape} but {what}={expected}")
        if batched and arr.shape[0] != out[0].shape[0]:
            raise InputError(
                f"{names[0]}.shape={out[0].shape} but {name}.shape={arr.shape}: "
                "every state array needs the same number of samples"
            )
        check_finite(arr, name, robot.dof_names if name != names[0] else None)
    return batched, out


def check_temperature(robot: Robot, temp, dq: np.ndarray) -> np.ndarray | None:
    """The temperature ``temp`` [degC or K] broadcast to the shape of ``dq`` (checked
    ``dq``: (nv,) or (N, nv)), or None when not given: a scalar, one column ((1,) or
    (N, 1)) for every joint, or one per joint; finite."""
    if temp is None:
        return None
    t = as_float_array(temp, "temp", ndim=(0, 1, 2))
    if t.ndim and (
        t.ndim != dq.ndim or t.shape[:-1] != dq.shape[:-1] or t.shape[-1] not in (1, robot.nv)
    ):
        raise InputError(
            f"temp.shape={t.shape} but dq.shape={dq.shape}: give one temperature column per "
            f"joint ({robot.nv}) or one column for every joint, one row per sample"
        )
    check_finite(np.atleast_1d(t), "temp")
    return np.ascontiguousarray(np.broadcast_to(t, dq.shape))


# ---------------------------------------------------------------- public API
def regressor(robot: Robot, q, dq, ddq, *, temp=None) -> np.ndarray:
    """The joint torque regressor Y(q, dq, ddq) with the robot's joint terms.

    Parameters
    ----------
    q
        joint positions [rad or m], shape (nq,) or (N, nq)
    dq
        joint velocities [rad/s or m/s], shape (nv,) or (N, nv)
    ddq
        joint accelerations [rad/s^2 or m/s^2], shape (nv,) or (N, nv)
    temp
        the measured temperature [degC or K] of the ``temperature`` law (module docstring)

    Returns
    -------
    Y of shape (nv, p) for one sample, (N, nv, p) for N samples, such that
    ``Y @ theta`` is the joint torque [N m or N] of the full inverse dynamics
    (rigid bodies, armature, friction, offset and spring as enabled).
    ``Y.reshape(-1, p)`` is the sample-major stacked regressor.
    """
    batched, (q, dq, ddq) = check_states(robot, q=q, dq=dq, ddq=ddq)
    temp = check_temperature(robot, temp, dq)
    ev = robot.evaluator
    if not batched:
        return ev.regressor(q, dq, ddq, temp=temp)
    out = np.empty((q.shape[0], robot.nv, robot.n_parameters))
    for c in ev.iter_regressor(q, dq, ddq, DEFAULT_CHUNK, temp):
        out[c.start : c.stop] = c.Y
    return out


def slotine_li_regressor(robot: Robot, q, dq, v, w) -> np.ndarray:
    """Slotine-Li regressor: ``Y(q, dq, v, w) theta = M(q) v + C(q, dq) w + g(q) + joint terms``.

    The joint terms are evaluated with ``v`` as acceleration and ``w`` as
    velocity (``Ia v_j + fv w_j + fc sign(w_j) + fo + k q_j``), so that
    ``slotine_li_regressor(robot, q, dq, ddq, dq) == regressor(robot, q, dq, ddq)``.

    Parameters
    ----------
    q
        joint positions [rad or m], shape (nq,) or (N, nq)
    dq
        joint velocities [rad/s or m/s], shape (nv,) or (N, nv)
    v
        the vector multiplying M(q) (reference acceleration), shape like dq
    w
        the vector multiplying C(q, dq) (reference velocity), shape like dq

    Returns
    -------
    Y of shape (nv, p) or (N, nv, p).
    """
    batched, (q, dq, v, w) = check_states(robot, q=q, dq=dq, v=v, w=w)
    ev = robot.evaluator
    if not batched:
        return ev.slotine_li(q, dq, v, w)
    out = np.empty((q.shape[0], robot.nv, robot.n_parameters))
    for c in ev.iter_slotine_li(q, dq, v, w, DEFAULT_CHUNK):
        out[c.start : c.stop] = c.Y
    return out


def iter_regressor(
    robot: Robot, q, dq, ddq, chunk: int = DEFAULT_CHUNK, *, temp=None
) -> Iterator[RegressorChunk]:
    """Y(q, dq, ddq) over N samples, ``chunk`` samples at a time (``temp``: see the top).

    Memory is O(chunk * nv * p) whatever N. Each yielded
    :class:`RegressorChunk` is a view of one reused buffer.
    """
    if int(chunk) < 1:
        raise InputError(f"chunk must be a positive number of samples, got {chunk}")
    batched, (q, dq, ddq) = check_states(robot, q=q, dq=dq, ddq=ddq)
    if not batched:
        raise InputError(f"iter_regressor takes N samples (2-D arrays), got q.shape={q.shape}")
    temp = check_temperature(robot, temp, dq)
    check_regressor_buffer(min(int(chunk), max(q.shape[0], 1)), robot.nv, robot.n_parameters)
    return robot.evaluator.iter_regressor(q, dq, ddq, int(chunk), temp)


def iter_slotine_li_regressor(
    robot: Robot, q, dq, v, w, chunk: int = DEFAULT_CHUNK
) -> Iterator[RegressorChunk]:
    """The Slotine-Li regressor over N samples, ``chunk`` at a time (see :func:`iter_regressor`)."""
    if int(chunk) < 1:
        raise InputError(f"chunk must be a positive number of samples, got {chunk}")
    batched, (q, dq, v, w) = check_states(robot, q=q, dq=dq, v=v, w=w)
    if not batched:
        raise InputError(
            f"iter_slotine_li_regressor takes N samples (2-D arrays), got q.shape={q.shape}"
        )
    return robot.evaluator.iter_slotine_li(q, dq, v, w, int(chunk))


def joint_torques(
    robot: Robot, theta, q, dq, ddq=None, *, armature: bool = True, temp=None
) -> np.ndarray:
    """Torques of the joint-level terms alone, shape (nv,) or (N, nv) [N m or N].

    ``Ia ddq + fv dq + fc sign(dq) + fo + k q + ...`` for the enabled terms with the
    values in ``theta`` (shape (p,)). With ``ddq=None`` or ``armature=False`` the
    armature term is left out (for inverse and forward dynamics by Pinocchio, where
    armature belongs in the mass matrix: see :meth:`Robot.with_parameters`). The motor
    terms of a transmission (:mod:`manip_id.robot.transmission`) are added through ``R^T``; their
    rotor inertia ``R^T diag(Ia) R ddq`` (not a Pinocchio armature when ``R`` couples
    joints) is left out only with ``ddq=None``. The
    ``load`` law needs ``ddq``, the ``temperature`` law ``temp`` (module docstring).
    """
    theta = as_float_array(theta, "theta", ndim=1)
    if theta.shape[0] != robot.n_parameters:
        raise InputError(f"{theta.shape=} but robot.n_parameters={robot.n_parameters}")
    ev = robot.evaluator
    if ddq is None:
        ev.refuse_load("joint_torques without ddq")
    acc = np.zeros_like(np.asarray(dq, dtype=float)) if ddq is None else ddq
    _, (q, dq, acc) = check_states(robot, q=q, dq=dq, ddq=acc)
    temp = check_temperature(robot, temp, dq)
    out, motors = np.zeros_like(dq), ev.motors
    if motors is not None:  # motor terms through R^T (Ia: its reflected inertia R^T Ia R ddq)
        coef_m = theta[ev.motor_start :].reshape(motors.n, -1).copy()
        coef_m[:, 0] *= ddq is not None or "Ia" not in motors.term_names  # Ia: the first
        out += motors.torques(coef_m.ravel(), dq, acc)
    if not ev.terms:
        return out
    vals = ev.joint_values(q, dq, acc, temp)  # (..., nv, nt)
    coef = robot.layout.joint_block(theta)
    if (ddq is None or not armature) and "Ia" in ev.terms:
        coef = coef.copy()
        coef[:, ev.terms.index("Ia")] = 0.0
    return out + np.einsum("...jt,jt->...j", vals, coef)
