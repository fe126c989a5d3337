"""The joint controller of a closed-loop log: PD or PID gains, and where its reference is.

A log recorded in closed loop holds, besides ``q``, ``dq`` and the commanded ``tau``, the
reference the controller tracked. The controller is decentralized, per joint ``j``::

    e_j  = q_ref,j - q_j                       [rad or m]
    de_j = dq_ref,j - dq_j                     [rad/s or m/s]
    tau_j = kp_j e_j + kd_j de_j + ki_j sum_k e_j,k dt      [N m or N]

(``ki = 0``: a PD without feed-forward; the integral is the rectangle sum over the control
periods, the error of the current period included). The controller file (TOML)::

    kp = [800.0, 800.0, 400.0]     # [N m/rad], one per active joint
    kd = [40.0, 40.0, 20.0]        # [N m s/rad]
    ki = [100.0, 100.0, 50.0]      # [N m/(rad s)], optional (PID)
    [reference]                    # optional: the log's reference columns
    q = "qref"                     # default "qref"
    dq = "dqref"                   # default "dqref"

The reference columns follow the package's column conventions: in an NPZ log, arrays
``qref`` and ``dqref`` of shape (N, nv); in a CSV log, columns ``qref_<joint>`` and
``dqref_<joint>`` (the ``q_``/``dq_`` prefixes of the measured signals do not match them).

:func:`track` runs the loop on any forward dynamics ``ddq = f(q, dq, tau)``: the torque is
computed at each sample and held over the period (zero-order hold), integrated in
``substeps`` semi-implicit Euler steps, as the closed-loop plant integrates
(:class:`manip_id.control.closed_loop.Plant`).
"""

from __future__ import annotations

import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._io.fields import Fields
from ._io.reading import read_toml
from .errors import DataError, InputError

#: Default names of the reference columns (NPZ arrays; CSV prefixes ``<name>_<joint>``).
REFERENCE_COLUMNS = ("qref", "dqref")
#: Prefixes of a CSV log's measured columns: no reference name may start with them.
MEASURED_PREFIXES = ("q_", "dq_", "ddq_", "tau_", "temp_")
#: Keys of a controller file.
KEYS = ("kp", "kd", "ki", "reference")


@dataclass(frozen=True)
class Controller:
    """A decentralized PD/PID joint controller (module docstring).

    Attributes
    ----------
    kp, kd : numpy.ndarray
        proportional [N m/rad] and derivative [N m s/rad] gains, shape (nv,), >= 0.
    ki : numpy.ndarray
        integral gains [N m/(rad s)], shape (nv,), >= 0 (None given: zeros, a PD).
    q_column, dq_column : str
        names of the reference columns of the log.
    source : str
        where it was read from ("" when built in code).
    """

    kp: np.ndarray
    kd: np.ndarray
    ki: np.ndarray
    q_column: str = REFERENCE_COLUMNS[0]
    dq_column: str = REFERENCE_COLUMNS[1]
    source: str = ""

    def __post_init__(self):
        kp = np.atleast_1d(np.asarray(self.kp, dtype=float))
        nv = kp.shape[0]
        ki = np.zeros(nv) if self.ki is None else self.ki
        for name, value in (("kp", kp), ("kd", self.kd), ("ki", ki)):
            arr = np.atleast_1d(np.asarray(value, dtype=float))
            if arr.shape != (nv,):
                raise InputError(f"controller {name} has shape {arr.shape}, expected ({nv},)")
            if not np.all(np.isfinite(arr)) or np.any(arr < 0):
                raise InputError(f"controller {name} must be finite and >= 0, got {arr}")
            object.__setattr__(self, name, arr)
        if not np.any(kp > 0):
            raise InputError("controller kp must hold a positive gain")
        for name in ("q_column", "dq_column"):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise InputError(f"controller {name} must be a non-empty name")
        if self.q_column == self.dq_column:
            raise InputError(f"the reference columns are both {self.q_column!r}")

    @property
    def nv(self) -> int:
        """Number of joints."""
        return int(self.kp.shape[0])

    @property
    def kind(self) -> str:
        """``"pid"`` with an integral gain, else ``"pd"``."""
        return "pid" if np.any(self.ki > 0) else "pd"

    def check_size(self, nv: int, what: str = "the robot") -> None:
        """Raise :class:`InputError` unless the controller has ``nv`` joints."""
        if self.nv != nv:
            where = f"{self.source}: " if self.source else ""
            raise InputError(
                f"{where}the controller has gains for {self.nv} joints but {what} has nv={nv}"
            )

    def to_dict(self) -> dict:
        """The controller file's table (:func:`load_controller` reads it back)."""
        return {
            "kind": self.kind,
            "kp": self.kp.tolist(),
            "kd": self.kd.tolist(),
            "ki": self.ki.tolist(),
            "reference": {"q": self.q_column, "dq": self.dq_column},
            "source": self.source,
        }


def load_controller(path, nv: int | None = None) -> Controller:
    """The :class:`Controller` of a TOML file (module docstring), checked against ``nv``
    joints when given; every bad key is one :class:`InputError` naming the file and key."""
    path = Path(path).expanduser()
    raw = read_toml(path, "controller file", error=InputError)
    f = Fields(path, InputError)
    f.known_names(raw, KEYS, "key")
    if "kp" not in raw or "kd" not in raw:
        missing = [k for k in ("kp", "kd") if k not in raw]
        raise InputError(f"{path}: missing {', '.join(missing)} (gains per joint)")
    gains = {}
    for key in ("kp", "kd", "ki"):
        if key not in raw:
            continue
        items = f.list(raw[key], key, nonempty=True)
        gains[key] = np.array(
            [f.number(v, f"{key}[{i}]", minimum=0.0) for i, v in enumerate(items)]
        )
        if nv is not None and len(items) != nv:
            raise InputError(
                f"{path}: {key} must be a list of {nv} gains (one per active joint), "
                f"got {len(items)}"
            )
    n = len(gains["kp"])
    for key, arr in gains.items():
        if len(arr) != n:
            raise InputError(f"{path}: {key} has {len(arr)} gains but kp has {n}")
    if not np.any(gains["kp"] > 0):
        raise InputError(f"{path}: kp must hold a positive gain, got all zeros")
    ref = f.object(raw.get("reference", {}), "reference")
    f.known_names(ref, ("q", "dq"), "reference key")
    q_col = f.text(ref.get("q", REFERENCE_COLUMNS[0]), "reference.q")
    dq_col = f.text(ref.get("dq", REFERENCE_COLUMNS[1]), "reference.dq")
    for key, name in (("reference.q", q_col), ("reference.dq", dq_col)):
        if name.startswith(MEASURED_PREFIXES):
            raise InputError(
                f"{path}: {key} {name!r} starts like a measured column "
                f"({', '.join(MEASURED_PREFIXES)}): a CSV reader would take its columns for "
                "the measured ones; e.g. 'qref'"
            )
        if not (name.isidentifier() and name.endswith("ref")):
            raise InputError(
                f"{path}: {key} must be a column name ending in 'ref' (letters, digits, _; "
                f"an NPZ log's reader skips such arrays), got {name!r}"
            )
    if q_col == dq_col:
        raise InputError(f"{path}: reference.q and reference.dq are both {q_col!r}")
    ki = gains.get("ki", np.zeros(n))
    return Controller(gains["kp"], gains["kd"], ki, q_col, dq_col, str(path))


def reference_names(controller: Controller | None) -> tuple[str, ...]:
    """The NPZ arrays a closed-loop log may hold beside a dataset's (default names too)."""
    names = set(REFERENCE_COLUMNS)
    if controller is not None:
        names |= {controller.q_column, controller.dq_column}
    return tuple(sorted(names))


def read_reference(
    path, controller: Controller, nv: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t, q_ref, dq_ref)`` of a log file (NPZ or CSV): time stamps [s] (N,) and the
    reference columns named by ``controller``, (N, nv) each."""
    path = Path(path).expanduser()
    names = (controller.q_column, controller.dq_column)
    if path.suffix.lower() == ".npz":
        try:
            with np.load(path, allow_pickle=False) as z:
                found = set(z.files)
                missing = [n for n in ("t", *names) if n not in found]
                if missing:
                    raise DataError(
                        f"{path}: no reference array(s) {', '.join(missing)} for the controller "
                        f"(found {', '.join(sorted(found))})"
                    )
                t, qr, dqr = (np.asarray(z[n], dtype=float) for n in ("t", *names))
        except (OSError, ValueError, zipfile.BadZipFile) as exc:
            raise DataError(f"cannot read the reference of {path}: {exc}") from exc
    elif path.suffix.lower() == ".csv":
        t, qr, dqr = _csv_reference(path, names)
    else:
        raise DataError(
            f"{path}: the reference of a closed-loop log is read from NPZ or CSV files, "
            f"not {path.suffix or 'a folder'}"
        )
    for name, arr in zip(names, (qr, dqr), strict=True):
        if arr.ndim != 2 or arr.shape != (t.shape[0], nv):
            raise DataError(f"{path}: {name} has shape {arr.shape}, expected ({t.shape[0]}, {nv})")
        if not np.all(np.isfinite(arr)):
            raise DataError(f"{path}: {name} holds non-finite values")
    return t, qr, dqr


def check_reference(path, controller: Controller) -> None:
    """Refuse, before any work, a log (NPZ or CSV) without the controller's reference
    columns: an NPZ's member names, a CSV's header alone are read."""
    path = Path(path).expanduser()
    names = (controller.q_column, controller.dq_column)
    try:
        if path.suffix.lower() == ".npz":
            with zipfile.ZipFile(path) as zf:
                found = {n[:-4] for n in zf.namelist() if n.endswith(".npy")}
            missing = [n for n in names if n not in found]
        else:
            with open(path, encoding="utf-8-sig") as fh:
                header = [h.strip() for h in fh.readline().strip().split(",")]
            missing = [n for n in names if not any(h.startswith(n + "_") for h in header)]
    except (OSError, UnicodeDecodeError, zipfile.BadZipFile) as exc:
        raise DataError(f"cannot read the reference of {path}: {exc}") from exc
    if missing:
        where = "arrays" if path.suffix.lower() == ".npz" else "columns <name>_<joint>"
        raise DataError(
            f"{path}: no reference {where} {', '.join(missing)} for the controller "
            f"{controller.source or ''} (a closed-loop log holds the reference it tracked)"
        )


def _csv_reference(path: Path, names) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    try:
        with open(path, encoding="utf-8-sig") as fh:
            header = [h.strip() for h in fh.readline().strip().split(",")]
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise DataError(f"cannot read the reference of {path}: {exc}") from exc
    tcol = [i for i, h in enumerate(header) if h.lower() in ("t", "time")]
    if len(tcol) != 1:
        raise DataError(f"{path}: the reference needs one t column, found {len(tcol)}")
    cols = []
    for name in names:
        idx = [i for i, h in enumerate(header) if h.startswith(name + "_")]
        if not idx:
            raise DataError(f"{path}: no reference columns {name}_<joint> for the controller")
        cols.append(data[:, idx])
    return data[:, tcol[0]], cols[0], cols[1]


def on_grid(t_ref, values, t) -> np.ndarray:
    """``values`` (N, nv) sampled at ``t_ref`` (N,), linearly interpolated at ``t`` (M,)."""
    t_ref, t = np.asarray(t_ref, float), np.asarray(t, float)
    lo, hi = t_ref[0] - 1e-9, t_ref[-1] + 1e-9
    if t[0] < lo or t[-1] > hi:
        raise DataError(
            f"the reference spans {t_ref[0]:.6g}..{t_ref[-1]:.6g} s but the data "
            f"{t[0]:.6g}..{t[-1]:.6g} s"
        )
    return np.column_stack([np.interp(t, t_ref, values[:, j]) for j in range(values.shape[1])])


@dataclass
class Tracked:
    """One closed-loop run of :func:`track`, sampled at the control instants.

    ``q`` (N, nv), ``dq`` (N, nv): the states the controller read; ``tau`` (N, nv): the
    commanded torques; ``ddq`` (N, nv): the accelerations at the samples under them.
    ``diverged``: the state left the finite numbers (the arrays are cut there).
    """

    q: np.ndarray
    dq: np.ndarray
    tau: np.ndarray
    ddq: np.ndarray
    diverged: bool = False


def track(
    acceleration: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray],
    controller: Controller,
    q_ref,
    dq_ref,
    start,
    dt: float,
    *,
    substeps: int = 1,
    measure: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None,
) -> Tracked:
    """The closed loop of ``controller`` on the dynamics ``ddq = acceleration(q, dq, tau)``.

    At each sample ``k`` (period ``dt`` [s]) the controller reads ``measure(q, dq)`` (the
    true state when None), computes ``tau_k`` (module docstring) and holds it over the
    period, integrated in ``substeps`` semi-implicit Euler steps from ``start`` =
    ``(q0, dq0)``.
    ``q_ref``, ``dq_ref``: (N, nv). Positions are added linearly (``nq == nv``).
    """
    q_ref, dq_ref = np.asarray(q_ref, float), np.asarray(dq_ref, float)
    n, nv = q_ref.shape
    controller.check_size(nv, "the reference")
    if int(substeps) != substeps or substeps < 1:
        raise InputError(f"substeps must be a positive integer, got {substeps}")
    h = dt / substeps
    q, v = (np.array(x, dtype=float) for x in start)
    out_q, out_v, out_t, out_a = (np.empty((n, nv)) for _ in range(4))
    integral = np.zeros(nv)
    kp, kd, ki = controller.kp, controller.kd, controller.ki
    for k in range(n):
        qm, vm = (q, v) if measure is None else measure(q, v)
        e = q_ref[k] - qm
        integral += e * dt
        tau = kp * e + kd * (dq_ref[k] - vm) + ki * integral
        out_q[k], out_v[k], out_t[k] = qm, vm, tau
        for s in range(substeps):
            a = acceleration(q, v, tau)
            if s == 0:
                out_a[k] = a
            v = v + h * a
            q = q + h * v
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
            m = k + 1
            return Tracked(out_q[:m], out_v[:m], out_t[:m], out_a[:m], diverged=True)
    return Tracked(out_q, out_v, out_t, out_a)


__all__ = [
    "REFERENCE_COLUMNS",
    "Controller",
    "Tracked",
    "check_reference",
    "load_controller",
    "on_grid",
    "read_reference",
    "reference_names",
    "track",
]
