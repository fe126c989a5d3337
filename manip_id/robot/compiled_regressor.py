"""The rigid-body joint torque regressor for a block of samples, compiled with numba.

The same quantity as ``pinocchio.computeJointTorqueRegressor`` (one call per sample),
evaluated for N samples in one compiled loop, so that no Python work is done per sample.
It is the recursive Newton-Euler algorithm written for the regressor (Atkeson, An and
Hollerbach 1986), in Pinocchio's conventions: spatial vectors ``[linear; angular]``,
body ``i``'s ten parameters ``pi_i = [m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` in
the frame of joint ``i`` (first moments and inertia about that frame's origin).

Forward pass, for each joint ``i`` with parent ``lambda(i)`` and motion subspace ``S_i``::

    X_i = M0_i * M_J(q_i)                              (parent -> joint frame, SE3)
    v_i = X_i^-1 v_lambda(i) + S_i dq_i                [m/s, rad/s]
    a_i = X_i^-1 a_lambda(i) + S_i ddq_i + v_i x S_i dq_i,   a_0 = -g  [m/s^2, rad/s^2]

Body ``i``'s spatial force is linear in its parameters, ``f_i = I_i a_i + v_i x* I_i v_i
= A(v_i, a_i) pi_i`` with ``A`` of shape (6, 10). Backward pass: joint ``j`` feels the
force of every body ``i`` of its subtree, carried to frame ``j``::

    Y[j, 10 (i-1) : 10 i] = S_j^T  jX*_i  A(v_i, a_i)

Supported joints: revolute and prismatic about any axis (Pinocchio's RX/RY/RZ, PX/PY/PZ,
the unaligned ones) and unbounded revolute joints (``q = (cos, sin)``); fixed joints are
already merged by Pinocchio. :func:`compile_model` returns ``None`` for any other model
(free-flyer, spherical, mimic, ...), and the caller keeps the per-sample Pinocchio path.

numba is an optional dependency (``pip install 'manip_id[fast]'``): it is imported only
when a compiled regressor is first asked for, and its compiled code is cached on disk.
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .._numba import note_compile, note_numba_warm, numba_available
from ..errors import InputError

# joint kinds of the compiled kernel
REVOLUTE = 0
PRISMATIC = 1
UNBOUNDED = 2

#: environment switch (inherited by forked and local Dask workers): ``auto`` (default),
#: ``compiled`` or ``pinocchio``; ``manip-id ... --regressor MODE`` sets it
ENV = "MANIP_ID_REGRESSOR"
MODES = ("auto", "compiled", "pinocchio")
#: in ``auto`` mode the kernel is used once an evaluator has seen this many samples: below
#: it, importing numba and loading the compiled code (~0.5 s a process) costs more than the
#: ~2 us a sample it saves (unless numba is loaded already: :func:`numba_warm`)
AUTO_SAMPLES = 200_000


@dataclass(frozen=True)
class CompiledModel:
    """A kinematic tree as flat arrays for the compiled kernel (one row per joint).

    ``parent``: index of the parent joint (-1 for the universe), shape (n,);
    ``kind``: REVOLUTE, PRISMATIC or UNBOUNDED; ``axis``: unit axis in the joint frame,
    shape (n, 3); ``rot0``, ``pos0``: the joint placement in its parent's frame, shapes
    (n, 3, 3) and (n, 3) [m]; ``idx_q``, ``idx_v``: first coordinate of the joint in q and v;
    ``gravity``: the linear gravity [m/s^2], shape (3,).
    """

    parent: np.ndarray
    kind: np.ndarray
    axis: np.ndarray
    rot0: np.ndarray
    pos0: np.ndarray
    idx_q: np.ndarray
    idx_v: np.ndarray
    gravity: np.ndarray
    nv: int

    @property
    def n_rigid(self) -> int:
        """Number of rigid-body columns, 10 per joint [-]."""
        return 10 * self.parent.shape[0]


_KINDS = {
    **{f"JointModelR{a}": REVOLUTE for a in "XYZ"},
    **{f"JointModelP{a}": PRISMATIC for a in "XYZ"},
    **{f"JointModelRUB{a}": UNBOUNDED for a in "XYZ"},
    "JointModelRevoluteUnaligned": REVOLUTE,
    "JointModelPrismaticUnaligned": PRISMATIC,
    "JointModelRevoluteUnboundedUnaligned": UNBOUNDED,
}


def _joint_kind(model: pin.Model, i: int) -> tuple[int, np.ndarray] | None:
    """(kind, unit axis in the joint frame) of joint ``i``, or None when not covered.

    The axis is read from the joint's motion subspace S (angular part for revolute
    joints, linear part for prismatic ones), which is constant for these joints.
    """
    joint = model.joints[i]
    kind = _KINDS.get(joint.shortname())
    if kind is None or joint.nv != 1:
        return None
    jdata = joint.createData()
    joint.calc(jdata, pin.neutral(model), np.zeros(model.nv))
    S = np.asarray(jdata.S, dtype=float).reshape(6)
    axis = S[:3] if kind == PRISMATIC else S[3:]
    return kind, axis / np.linalg.norm(axis)


def describe_model(model: pin.Model) -> CompiledModel | None:
    """The flat description of ``model``, or None when a joint is not covered."""
    n = model.njoints - 1
    kinds, axes = [], []
    for i in range(1, model.njoints):
        found = _joint_kind(model, i)
        if found is None:
            return None
        kinds.append(found[0])
        axes.append(found[1])
    placements = [model.jointPlacements[i] for i in range(1, model.njoints)]
    return CompiledModel(
        parent=np.array([model.parents[i] - 1 for i in range(1, model.njoints)], dtype=np.int64),
        kind=np.array(kinds, dtype=np.int64),
        axis=np.ascontiguousarray(np.array(axes, dtype=float).reshape(n, 3)),
        rot0=np.ascontiguousarray(np.array([M.rotation for M in placements]).reshape(n, 3, 3)),
        pos0=np.ascontiguousarray(np.array([M.translation for M in placements]).reshape(n, 3)),
        idx_q=np.array([model.idx_qs[i] for i in range(1, model.njoints)], dtype=np.int64),
        idx_v=np.array([model.idx_vs[i] for i in range(1, model.njoints)], dtype=np.int64),
        gravity=np.array(model.gravity.linear, dtype=float),
        nv=int(model.nv),
    )


_KERNEL = None
_MOMENTUM = None


def _kernel():
    """The compiled block kernel (numba is imported here: an optional heavy dependency)."""
    global _KERNEL
    if _KERNEL is None:
        from ._regressor_kernel import build  # imports numba, compiles or loads the cache

        _KERNEL = build()
        note_compile(_KERNEL)  # one line when it compiles (nothing cached)
    return _KERNEL


def mode() -> str:
    """The regressor mode of this process (``MANIP_ID_REGRESSOR``), one of :data:`MODES`."""
    value = os.environ.get(ENV, "auto").strip().lower() or "auto"
    if value not in MODES:
        raise InputError(f"{ENV} must be one of {', '.join(MODES)}, got {value!r}")
    return value


def set_mode(value: str) -> None:
    """Set the regressor mode for this process and the workers it starts."""
    value = str(value).strip().lower()
    if value not in MODES:
        raise InputError(f"the regressor must be one of {', '.join(MODES)}, got {value!r}")
    os.environ[ENV] = value


#: samples announced by :func:`planned_samples` for the current run (0: none)
_planned = 0
#: samples evaluated in blocks by this process, every evaluator together
_seen = 0


def planned() -> int:
    """Samples announced for the current run by :func:`planned_samples` [-]."""
    return _planned


def count_samples(n: int) -> int:
    """Add ``n`` samples to those this process has evaluated in blocks; the new total.

    The kernel's cost is paid once per process (importing numba, loading its code), so
    ``auto`` counts a process's samples, not an evaluator's: a Dask worker gets a new
    robot (and evaluator) with every task, and would otherwise never reach the kernel.
    """
    global _seen
    _seen += int(n)
    return _seen


@contextmanager
def planned_samples(n: int):
    """Announce a run over ``n`` samples (in this process and the workers it forks).

    In ``auto`` mode an evaluator then uses the compiled kernel from the first block
    when ``n >= AUTO_SAMPLES``, instead of after having seen that many samples; and the
    kernel is loaded here, once, so that forked workers inherit it rather than each
    importing numba and loading it again (about 0.5 s a process).
    """
    global _planned
    previous = _planned
    _planned = max(int(n), 0)
    try:
        if mode() != "pinocchio" and _planned >= AUTO_SAMPLES and numba_available():
            _kernel()
        yield
    finally:
        _planned = previous


def compile_model(model: pin.Model) -> CompiledModel | None:
    """The model for the compiled kernel, or None (numba missing, mode ``pinocchio``, or
    a joint the kernel does not cover); the caller then uses Pinocchio per sample."""
    if mode() == "pinocchio":
        return None
    desc = describe_model(model)
    if desc is None or not numba_available():
        return None
    return desc


def rigid_block(desc: CompiledModel, q, dq, ddq, out: np.ndarray, gravity: bool = True) -> None:
    """Write Y_rigid(q_k, dq_k, ddq_k) into ``out[k]`` for every sample of the block.

    ``q``: shape (N, nq); ``dq``, ``ddq``: shape (N, nv) (float64, C-contiguous);
    ``out``: shape (N, nv, n_rigid) or a strided view of that shape (written in place,
    other columns of a wider buffer untouched). ``gravity=False`` evaluates the
    gravity-free model (the Slotine-Li velocity part).
    """
    g = desc.gravity if gravity else np.zeros(3)
    tree = (desc.parent, desc.kind, desc.axis, desc.rot0, desc.pos0, desc.idx_q, desc.idx_v, g)
    _kernel()(tree, q, dq, ddq, out)
    note_numba_warm()


def momentum_block(desc: CompiledModel, q, dq, yp: np.ndarray, yh: np.ndarray) -> None:
    """Write the rigid momentum regressors ``Y_p`` into ``yp`` and ``g - dK/dq`` into ``yh``.

    ``q`` (N, nq), ``dq`` (N, nv) float64 C-contiguous; ``yp``, ``yh`` (N, nv, >= n_rigid),
    written in their rigid columns only (see :func:`manip_id.models.momentum_regressors`).
    """
    global _MOMENTUM
    if _MOMENTUM is None:
        from ._regressor_kernel import build_momentum  # imports numba (optional, heavy)

        _MOMENTUM = build_momentum()
        note_compile(_MOMENTUM)
    tree = (desc.parent, desc.kind, desc.axis, desc.rot0, desc.pos0, desc.idx_q, desc.idx_v)
    _MOMENTUM((*tree, desc.gravity), q, dq, yp, yh)
