"""The exceptions of manip_id: one root, subclasses that carry data.

Every error raised on bad input is a :class:`ManipIdError`; the command line
prints its message on one line and exits with status 2. Errors raised by a
library we call (Pinocchio, NumPy, SciPy) are re-raised as ours, ``from`` the
cause.
"""

from __future__ import annotations

from collections.abc import Sequence


class ManipIdError(Exception):
    """Root of every error manip_id raises on purpose."""


class InputError(ManipIdError, ValueError):
    """An argument has the wrong shape, type, value or contains NaN/Inf."""


class RobotError(ManipIdError):
    """A robot cannot be loaded: unknown name, unreadable URDF, unsupported model."""


class DataError(ManipIdError):
    """A dataset file is missing, malformed or inconsistent with the robot."""


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

    Attributes
    ----------
    rank: numerical rank of the regressor.
    n_columns: number of columns (parameters) asked for.
    directions: the unexcited directions as readable expressions in parameter names.
    """

    def __init__(self, message: str, rank: int, n_columns: int, directions: Sequence[str] = ()):
        super().__init__(message)
        self.rank = rank
        self.n_columns = n_columns
        self.directions = list(directions)
