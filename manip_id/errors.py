"""The exceptions of manip_id: one root, subclasses that carry data.

Every error raised on bad input is a :class:`ManipIdError`; the command line
prints its message on one line and exits with status 2. Errors raised by a
library we call (Pinocchio, NumPy, SciPy) are re-raised as ours, ``from`` the
cause.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Sequence

import numpy as np


class ManipIdError(Exception):
    """Root of every error manip_id raises on purpose."""


class InputError(ManipIdError, ValueError):
    """An argument has the wrong shape, type, value or contains NaN/Inf."""


class RobotError(ManipIdError):
    """A robot cannot be loaded: unknown name, unreadable URDF, unsupported model."""


class OutputError(InputError):
    """An output path is refused before the work, or cannot be written.

    A missing parent folder, a folder where a file is expected, a special file, one of
    the inputs, the current directory or an ancestor of an input (for a folder).
    """


class ReportBusyError(OutputError):
    """Another run has claimed the report folder (of two concurrent runs, one wins)."""


# --- report folders (manip_id._io.report_folder, manip_id.viz.report) --------------
class ReportExistsError(InputError):
    """The report folder exists and is not empty, and ``force`` was not given.

    Attributes
    ----------
    path : str
        The report folder.
    """

    def __init__(self, path):
        self.path = str(path)
        super().__init__(
            f"report folder {self.path} exists and is not empty "
            "(use --force / force=True to replace it)"
        )

    def __reduce__(self):
        return (type(self), (self.path,))


# --- end of report folders ---------------------------------------------------------


class ResourceError(InputError):
    """A computation would not fit the machine (memory estimated before the work)."""


class DataError(ManipIdError):
    """A dataset file is missing, malformed or inconsistent with the robot."""


class MissingTemperatureError(DataError):
    """The ``temperature`` friction law was asked for, but the data carry no temperature.

    Attributes
    ----------
    source : str
        The file (or ``"the arrays"``) without a temperature.
    format : str
        Its format (``"csv"``, ``"npz"``, ``"rosbag"``, ...).
    fields : tuple of str
        The fields it does hold (``t``, ``q``, ``dq``, ``tau``, ...).
    """

    def __init__(self, source: str, format: str, fields: Sequence[str]):
        self.source, self.format, self.fields = str(source), str(format), tuple(fields)
        how = {
            "csv": "map its column(s) with --column temp=COLUMN (one per joint, or one for "
            "every joint; columns=... in the API)",
            "npz": "save a temp array of shape (N, nv), or (N,) for every joint",
            "rosbag": "a ROS 2 JointState bag carries no temperature: convert it to NPZ or "
            "CSV with a temp field",
        }.get(self.format, "give temp=... (shape (N, nv) or (N, 1))")
        super().__init__(
            f"the temperature friction law needs the measured temperature, but {self.source} "
            f"({self.format}) has no temp field (it holds {', '.join(self.fields)}): {how}"
        )


class InfeasibleTrajectoryError(ManipIdError):
    """A trajectory leaves the joint limits.

    Attributes
    ----------
    joint: name of the first offending joint.
    limit: which limit ("position", "velocity", "acceleration").
    excess: by how much the limit is exceeded, in the limit's unit.
    """

    def __init__(self, message: str, joint: str = "", limit: str = "", excess: float = 0.0):
        super().__init__(message)
        self.joint = joint
        self.limit = limit
        self.excess = excess


class RankDeficiencyError(ManipIdError):
    """The data do not excite every parameter that was asked for.

    The message is built from the fields; the directions are formatted by
    :func:`format_direction` wherever they come from.

    Attributes
    ----------
    rank: numerical rank of the regressor.
    n_columns: number of columns (parameters) asked for.
    directions: the unexcited directions as readable expressions in parameter names.
    subject: what has the rank, e.g. ``"these data of panda"`` (message only).
    what: what the columns are, e.g. ``"base parameter directions"`` (message only).
    hint: what to do about it (message only).
    """

    #: Directions shown in the message (all are in :attr:`directions`).
    SHOWN = 5

    def __init__(
        self,
        rank: int,
        n_columns: int,
        directions: Sequence[str] = (),
        *,
        subject: str = "the data",
        what: str = "parameter directions",
        hint: str = "",
    ):
        self.rank = int(rank)
        self.n_columns = int(n_columns)
        self.directions = [str(d) for d in directions]
        self.subject = subject
        self.what = what
        self.hint = hint
        super().__init__(self._message())

    def _message(self) -> str:
        dirs = self.directions
        shown = "; ".join(dirs[: self.SHOWN]) + ("; ..." if len(dirs) > self.SHOWN else "")
        text = f"{self.subject} excite only {self.rank} of {self.n_columns} {self.what}"
        if dirs:
            text += f"; unexcited ({len(dirs)}): {shown}"
        return text + (f" ({self.hint})" if self.hint else "")

    @classmethod
    def from_vectors(
        cls,
        rank: int,
        vectors: np.ndarray,
        names: Sequence[str] | None,
        *,
        scale: np.ndarray | None = None,
        **fields,
    ) -> RankDeficiencyError:
        """The error for directions given as the columns of ``vectors``, shape (p, k)."""
        vectors = np.asarray(vectors, dtype=float).reshape(np.shape(vectors)[0], -1)
        directions = [
            format_direction(vectors[:, i], names, scale=scale) for i in range(vectors.shape[1])
        ]
        return cls(rank, vectors.shape[0], directions, **fields)

    def __reduce__(self):
        kwargs = {"subject": self.subject, "what": self.what, "hint": self.hint}
        return (_rebuild, (type(self), (self.rank, self.n_columns, self.directions), kwargs))


class NumericalError(ManipIdError, ArithmeticError):
    """A computation failed numerically (divergence, a factorization that broke down).

    Distinct from :class:`InputError`: the inputs were valid, the numbers were not.

    Attributes
    ----------
    operation: what was being computed, e.g. ``"closed-loop simulation"``.
    reason: what went wrong, e.g. ``"the state diverged at t=0.1234 s"``.
    hint: what to try (may be empty).
    """

    def __init__(self, operation: str, reason: str, *, hint: str = ""):
        self.operation = operation
        self.reason = reason
        self.hint = hint
        super().__init__(f"{operation}: {reason}" + (f" ({hint})" if hint else ""))

    def __reduce__(self):
        return (_rebuild, (type(self), (self.operation, self.reason), {"hint": self.hint}))


class ModelMismatchError(InputError):
    """A model, or thresholds, made for another robot or other joints (the monitor, drift).

    Attributes
    ----------
    what: what does not fit, e.g. ``"the model's parameters"`` or ``"the thresholds' joints"``.
    expected: what the robot has (a short text).
    got: what came (a short text).
    """

    def __init__(self, what: str, expected: str, got: str):
        self.what = what
        self.expected = expected
        self.got = got
        super().__init__(f"{what}: not for this robot: expected {expected}, got {got}")

    def __reduce__(self):
        return (_rebuild, (type(self), (self.what, self.expected, self.got), {}))


class SolverError(ManipIdError):
    """The consistent solver failed or the problem is infeasible.

    Attributes
    ----------
    reason: what happened, e.g. ``"the problem is infeasible"``.
    solver: "sdp" or "logchol".
    status: the solver's own status string.
    """

    def __init__(self, reason: str, solver: str, status: str):
        self.reason = str(reason)
        self.solver = str(solver)
        self.status = str(status)
        super().__init__(f"{self.solver} solver: {self.reason} (status {self.status!r})")

    def __reduce__(self):
        return (_rebuild, (type(self), (self.reason, self.solver, self.status), {}))


class PhysicalConsistencyError(ManipIdError, ValueError):
    """A parameter vector that had to be physical is not.

    Attributes
    ----------
    what: the vector, e.g. ``"the prior (nominal parameters)"`` (message only).
    violations: each broken condition (:class:`manip_id.physics.consistency.Violation`: a body
        or parameter name, the condition, the value); the message shows the first four.
    """

    #: Violations shown in the message (all are in :attr:`violations`).
    SHOWN = 4

    def __init__(self, what: str, violations: Sequence[object]):
        self.what = str(what)
        self.violations = list(violations)
        n = self.SHOWN
        shown = "; ".join(str(v) for v in self.violations[:n])
        more = f"; ... {len(self.violations) - n} more" if len(self.violations) > n else ""
        super().__init__(f"{self.what} is not physically consistent: {shown}{more}")

    def __reduce__(self):
        return (_rebuild, (type(self), (self.what, self.violations), {}))


class ManipIdWarning(UserWarning):
    """Root of the warnings manip_id issues (each also recorded in its result's ``warnings``)."""


class RobotWarning(ManipIdWarning):
    """A robot model loaded with a simplification the user should know of (a ``<mimic>``
    joint of an example-robot-data robot modelled as independent)."""


class OutputWarning(ManipIdWarning):
    """An output was published, but something beside it needs the user's eye: a file saved
    into a ``--force`` folder during the run (kept, under a name given), or the staging
    folder of an earlier run that was killed."""


class DataWarning(ManipIdWarning):
    """Data that would make a figure mean less than it says: a validation part that
    repeats the training motion."""


class MonitorWarning(ManipIdWarning):
    """Collision-monitor bounds the user should look at: calibrated on the runs the model
    was identified on (in-sample, too tight on new runs)."""


class PayloadWarning(ManipIdWarning):
    """A payload or drive-gain result the user should look at (also in ``result.warnings``)."""


def _rebuild(cls, args, kwargs):
    return cls(*args, **kwargs)


#: Terms of a direction whose scaled coefficient is below this fraction of the lead's are
#: left out of its text.
DIRECTION_THRESHOLD = 1e-6


def format_direction(
    vector,
    names: Sequence[str] | None = None,
    *,
    lead: int | None = None,
    scale=None,
    threshold: float = DIRECTION_THRESHOLD,
) -> str:
    """A direction in parameter space as readable text, e.g. ``"a.m - 0.5*b.mcx"``.

    The one format of directions (unidentifiable, unexcited, regrouped): the
    ``lead`` term first with coefficient 1 (default: the largest scaled entry,
    the later one of a tie, as the QR analysis of :mod:`manip_id.identifiability` leads
    with the dependent, later, parameter),
    then the others in parameter order; four significant digits; a term whose
    scaled size ``|v_i| scale_i`` is below ``threshold`` times the lead's is
    left out.

    Parameters
    ----------
    vector: the direction, shape (p,).
    names: parameter names, length p (default ``theta[i]``).
    lead: index of the term written first.
    scale: column scale, shape (p,) (e.g. the regressor's column norms), default ones.
    threshold: relative size below which a term is not written.
    """
    v = np.asarray(vector, dtype=float).ravel()
    names = list(names) if names is not None else [f"theta[{i}]" for i in range(v.size)]
    if len(names) != v.size:
        raise InputError(f"{len(names)} names for a direction of {v.size} entries")
    s = np.ones(v.size) if scale is None else np.asarray(scale, dtype=float).ravel()
    size = np.abs(v) * s
    if lead is None:
        if not v.any():
            return "0"
        w = size if size.any() else np.abs(v)
        # ties go to the later parameter: the one the QR analysis calls dependent
        lead = int(np.flatnonzero(w >= (1.0 - 1e-9) * w.max())[-1])
    k = int(lead)
    if v[k] == 0:
        return "0"
    c = v / v[k]
    ref = max(float(size[k]), 1e-300)  # a lead of zero scale (a zero column) still leads
    order = [k] + [i for i in range(v.size) if i != k and size[i] > threshold * ref]
    out = ""
    for n, i in enumerate(order):
        mag = abs(float(c[i]))
        coef = "" if math.isclose(mag, 1.0, rel_tol=1e-9) else f"{mag:.4g}*"
        sign = "-" if c[i] < 0 else "+"
        out += f"{coef}{names[i]}" if n == 0 else f" {sign} {coef}{names[i]}"
    return out


# ------------------------------------------------------------------ export (helper export)
class CarriedInertiaError(ManipIdError):
    """An identified composite body cannot carry the nominal inertias of its rigid links.

    The export gives every link attached rigidly to a joint's body (fixed joints, joints
    locked for the identification) its nominal inertia and the joint's own link the
    identified composite minus them; for these bodies that remainder is not physical.

    Attributes
    ----------
    bodies: per body (its joint's name), the links it carries.
    min_eigenvalues: per body, the smallest eigenvalue of the remainder's pseudo-inertia
        [mixed kg / kg m^2].
    """

    def __init__(self, bodies: dict[str, list[str]], min_eigenvalues: dict[str, float]):
        self.bodies = {k: list(v) for k, v in bodies.items()}
        self.min_eigenvalues = {k: float(v) for k, v in min_eigenvalues.items()}
        shown = "; ".join(
            f"{j} (carrying {', '.join(links)}: smallest pseudo-inertia eigenvalue "
            f"{self.min_eigenvalues.get(j, math.nan):.4g})"
            for j, links in self.bodies.items()
        )
        super().__init__(
            "the identified bodies cannot carry the nominal inertias of their rigid links: "
            f"{shown} (export with carried='scaled' to give these links a consistent share)"
        )

    def __reduce__(self):
        return (_rebuild, (type(self), (self.bodies, self.min_eigenvalues), {}))


class ExportWarning(ManipIdWarning):
    """An export changed something the user should know of (a scaled share of carried links)."""


#: The most characters of a user's value that a message quotes (:func:`shorten`).
QUOTE_LIMIT = 80


def shorten(value, n: int = QUOTE_LIMIT) -> str:
    """``str(value)`` cut to ``n`` characters for quoting in a message (a 100 MB CSV header
    cell must not make a 100 MB error line): ``"abc... (1234567 characters)"``."""
    text = str(value)
    return text if len(text) <= n else f"{text[:n]}... ({len(text)} characters)"


def did_you_mean(word: str, choices, n: int = 1) -> str:
    """``" (did you mean 'panda'?)"`` for the ``n`` choices closest to ``word`` (difflib),
    or ``""`` when none is close: what follows a wrong name in an error message."""
    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=n, cutoff=0.6)
    if not close:
        return ""
    return " (did you mean " + " or ".join(repr(c) for c in close) + "?)"
