"""Errors that build their messages from their fields; one format for directions."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from conftest import get_robot

from manip_id.errors import (
    InputError,
    ManipIdError,
    NumericalError,
    RankDeficiencyError,
    format_direction,
)


def test_rank_deficiency_message_is_built_from_its_fields():
    err = RankDeficiencyError(
        2, 4, ["a - b", "c"], subject="these data of msd", what="base parameter directions"
    )
    text = str(err)
    assert "these data of msd excite only 2 of 4 base parameter directions" in text
    assert "unexcited (2): a - b; c" in text
    assert (err.rank, err.n_columns, err.directions) == (2, 4, ["a - b", "c"])
    many = RankDeficiencyError(0, 9, [f"d{i}" for i in range(9)], hint="excite more")
    assert "d4; ..." in str(many) and "d5" not in str(many) and str(many).endswith("(excite more)")


def test_errors_survive_pickling_with_their_fields():
    """Worker processes send errors back pickled: the fields must come back too."""
    err = RankDeficiencyError(1, 3, ["x"], hint="h")
    back = pickle.loads(pickle.dumps(err))
    assert type(back) is RankDeficiencyError and str(back) == str(err)
    assert (back.rank, back.n_columns, back.directions, back.hint) == (1, 3, ["x"], "h")
    num = pickle.loads(pickle.dumps(NumericalError("op", "went wrong", hint="try")))
    assert str(num) == "op: went wrong (try)" and num.hint == "try"
    assert isinstance(num, ManipIdError) and not isinstance(num, InputError)


def test_from_vectors_formats_with_the_one_formatter():
    v = np.array([[2.0, 0.0, -1.0]]).T
    err = RankDeficiencyError.from_vectors(2, v, ["a", "b", "c"])
    assert err.directions == [format_direction(v[:, 0], ["a", "b", "c"])] == ["a - 0.5*c"]
    assert err.n_columns == 3


def test_format_direction_checks_its_names():
    with pytest.raises(InputError, match="2 names for a direction of 3"):
        format_direction([1.0, 2.0, 3.0], ["a", "b"])
    assert format_direction([0.0, 0.0], ["a", "b"]) == "0"
    assert format_direction([0.0, 3.0]) == "theta[1]"


def test_closed_loop_divergence_is_a_numerical_error():
    from manip_id.control.adaptive import default_gains
    from manip_id.control.closed_loop import ClosedLoopOptions, simulate

    robot = get_robot("ur5")
    theta = robot.nominal_parameters
    gains = default_gains(robot, theta)
    # a derivative gain far beyond what a 100 Hz loop can integrate: the state blows up
    wild = type(gains)(**{**gains.__dict__, "kd": gains.kd * 1e6})
    with pytest.raises(NumericalError, match="closed-loop simulation: the state diverged"):
        simulate(
            robot,
            theta,
            theta,
            gains=wild,
            adapt=False,
            options=ClosedLoopOptions(duration=1.0, rate=100),
        )


def test_moved_errors_live_in_errors_and_keep_their_old_homes():
    """SolverError, PhysicalConsistencyError and PayloadWarning are defined in
    manip_id.errors, carry their data through pickling, and import from where they did."""
    from manip_id import errors
    from manip_id.estimators.consistent import SolverError as SE
    from manip_id.payload import PayloadWarning as PW
    from manip_id.physics.consistency import PhysicalConsistencyError as PC
    from manip_id.physics.consistency import Violation

    assert (PC, SE, PW) == (
        errors.PhysicalConsistencyError,
        errors.SolverError,
        errors.PayloadWarning,
    )
    assert issubclass(PW, errors.ManipIdWarning) and issubclass(PW, UserWarning)
    err = SE("the problem is infeasible", "sdp", "scale 1: infeasible")
    back = pickle.loads(pickle.dumps(err))
    assert str(back) == "sdp solver: the problem is infeasible (status 'scale 1: infeasible')"
    assert (back.reason, back.solver, back.status) == (err.reason, "sdp", err.status)
    vs = [Violation(f"j{i}", "mass m > 0 [kg]", -1.0 * i) for i in range(6)]
    pc = pickle.loads(pickle.dumps(PC("the prior", vs)))
    assert isinstance(pc, ManipIdError) and isinstance(pc, ValueError)
    assert pc.what == "the prior" and [v.name for v in pc.violations] == [v.name for v in vs]
    assert "j3: mass m > 0 [kg] (got -3)" in str(pc) and "... 2 more" in str(pc)
    assert "j4" not in str(pc)
