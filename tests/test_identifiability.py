"""Rank analysis: published base-parameter counts, the msd special case, bad input.

Independent checks: the published counts; numpy's own ``matrix_rank`` of the
stacked, column-scaled regressor at fresh random states; ``pinocchio.rnea``
torques reproduced by the base regressor; ``Y @ null_space == 0`` at states
the analysis never saw; exact recovery from noise-free msd data.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot
from scipy.integrate import solve_ivp

from manip_id import InputError, RobotError, regressor
from manip_id.errors import format_direction
from manip_id.identifiability import (
    BaseParameters,
    RankAnalysis,
    RFactorAccumulator,
    analyze,
    analyze_information,
    analyze_trajectory,
    structural_analysis,
)
from manip_id.robot.model import MANIPULATORS

FULL_FRICTION = ("viscous", "coulomb", "offset")


def _scaled_rank(Y: np.ndarray, rtol: float = 1e-8) -> int:
    """numpy's rank of the column-scaled stacked regressor at the documented relative tolerance.

    Columns below ``rtol`` of the largest are zero; singular values below ``rtol``
    of the largest are dropped (``identifiability.TOLERANCE_FLOOR``).
    """
    norms = np.linalg.norm(Y, axis=0)
    keep = norms > rtol * norms.max()
    Ys = Y[:, keep] / norms[keep]
    return int(np.linalg.matrix_rank(Ys, tol=rtol * np.linalg.norm(Ys, 2)))


@pytest.fixture(scope="module")
def panda_structural() -> RankAnalysis:
    return analyze(get_robot("panda"))


# ---------------------------------------------------------- published counts
@pytest.mark.parametrize(
    ("name", "options", "count"),
    [
        ("panda", {}, 43),
        ("panda", {"armature": True}, 48),
        ("panda", {"friction": FULL_FRICTION}, 64),
        ("ur3", {}, 36),
        ("ur5", {}, 36),
        ("ur10", {}, 36),
        ("ur3", {"armature": True}, 40),
        ("ur5", {"armature": True}, 40),
        ("ur10", {"armature": True}, 40),
    ],
)
def test_published_base_parameter_counts(name, options, count):
    robot = get_robot(name, **options)
    result = analyze(robot)
    assert result.rank == count
    assert result.base.n_base == count
    assert result.null_space.shape == (robot.n_parameters, robot.n_parameters - count)
    assert len(result.unidentifiable) == robot.n_parameters - count


@pytest.mark.parametrize("name", [n for n in MANIPULATORS if n not in ("panda", "ur3", "ur5")])
def test_every_manipulator_rank_and_null_space(name):
    try:
        robot = get_robot(name)
    except RobotError as exc:  # pragma: no cover - depends on the installed robot data
        pytest.skip(f"{name} does not load here: {exc}")
    result = analyze(robot)
    p = robot.n_parameters
    assert result.rank == result.base.n_base
    assert result.null_space.shape == (p, p - result.rank)
    assert result.base.independent.size + result.base.dependent.size == p
    # Independent: numpy's rank of the stacked regressor at states the analysis never saw.
    q, dq, ddq = robot.random_states(max(60, 3 * p // robot.nv), seed=123)
    Y = regressor(robot, q, dq, ddq).reshape(-1, p)
    assert _scaled_rank(Y) == result.rank
    scale = np.linalg.norm(Y, axis=0)
    assert np.abs(Y @ result.null_space).max() <= 1e-9 * scale.max()


# ----------------------------------------------------- base parameters, K
@pytest.mark.parametrize(
    ("name", "options"),
    [("panda", {}), ("ur5", {"armature": True}), ("panda", {"friction": FULL_FRICTION})],
)
def test_base_regressor_reproduces_rnea(name, options):
    robot = get_robot(name, **options)
    result = analyze(robot)
    q, dq, ddq = robot.random_states(5, seed=7)
    rng = np.random.default_rng(3)
    theta = robot.nominal_parameters + 0.1 * rng.standard_normal(robot.n_parameters)
    theta[: robot.n_rigid] = robot.nominal_parameters[: robot.n_rigid]  # keep bodies physical
    Y = regressor(robot, q, dq, ddq)
    tau_base = result.base.regressor(Y) @ result.base.to_base(theta)
    model = robot.with_parameters(theta)
    data = model.createData()
    for k in range(q.shape[0]):
        tau = pin.rnea(model, data, q[k], dq[k], ddq[k])
        # joint terms other than armature are not in rnea: add them from the columns
        extra = Y[k, :, robot.n_rigid :] @ theta[robot.n_rigid :]
        if robot.terms.armature:
            extra -= theta[robot.n_rigid :: len(robot.terms.enabled)][: robot.nv] * ddq[k]
        np.testing.assert_allclose(tau_base[k], tau + extra, rtol=1e-8, atol=1e-8)
    # Y_2 = Y_1 K at fresh states
    Ys = Y.reshape(-1, robot.n_parameters)
    np.testing.assert_allclose(
        Ys[:, result.base.dependent],
        Ys[:, result.base.independent] @ result.base.K,
        atol=1e-8 * np.abs(Ys).max(),
    )


def test_panda_expressions_regroup_like_the_symbolic_rules(panda_structural):
    base = panda_structural.base
    names = dict(zip(base.base_names, base.expressions, strict=True))
    # a vertical first axis: of link 1 only Izz (with link 2's Iyy regrouped into it) remains
    assert names["panda_joint1.IzzR"] == "panda_joint1.Izz + panda_joint2.Iyy"
    assert not [n for n in base.base_names if n.startswith("panda_joint1.") and "Izz" not in n]
    # every parameter of link 1 but Izz never enters the dynamics: each is its own direction
    for p in ("m", "mcx", "mcy", "mcz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz"):
        assert f"panda_joint1.{p}" in panda_structural.unidentifiable
    # masses of links 3..7 regroup with the 0.316 m offset (panda URDF: joint3 at y=-0.316)
    assert "0.316*panda_joint3.m" in names["panda_joint2.mcyR"]


def test_deterministic_for_a_seed():
    robot = get_robot("ur5")
    a, b = analyze(robot, seed=4), analyze(robot, seed=4)
    np.testing.assert_array_equal(a.base.independent, b.base.independent)
    np.testing.assert_array_equal(a.base.K, b.base.K)
    assert a.unidentifiable == b.unidentifiable
    c = analyze(robot, seed=5)  # other states, same structure
    np.testing.assert_array_equal(a.base.independent, c.base.independent)
    np.testing.assert_allclose(a.base.K, c.base.K, atol=1e-8)


def test_streaming_and_information_agree_with_stacked():
    robot = get_robot("ur5", armature=True)
    q, dq, ddq = robot.random_states(150, seed=11)
    Y = regressor(robot, q, dq, ddq)
    names = robot.parameter_names
    stacked = analyze(Y.reshape(-1, robot.n_parameters), names=names)
    three_d = analyze(Y, names=names)
    streamed = analyze_trajectory(robot, q, dq, ddq, structural=stacked)
    acc = RFactorAccumulator(robot.n_parameters)
    for k in range(0, 150, 40):
        acc.add(Y[k : k + 40])
    info = analyze_information(acc.information, names, n_rows=acc.n_rows)
    np.testing.assert_allclose(
        acc.information,
        Y.reshape(-1, robot.n_parameters).T @ Y.reshape(-1, robot.n_parameters),
        rtol=1e-9,
        atol=1e-9,
    )
    for r in (three_d, streamed, info):
        assert r.rank == stacked.rank == 40
        np.testing.assert_array_equal(r.base.independent, stacked.base.independent)
        np.testing.assert_allclose(r.base.K, stacked.base.K, atol=1e-6)
    np.testing.assert_allclose(three_d.singular_values, stacked.singular_values, rtol=1e-9)
    assert streamed.unexcited == []


def test_static_poses_leave_inertia_unexcited(panda_structural):
    """At rest (dq = ddq = 0) only gravity acts: the inertia directions are not excited."""
    robot = get_robot("panda")
    q, dq, ddq = robot.random_states(200, seed=21)
    dq[:] = 0.0
    ddq[:] = 0.0
    result = analyze_trajectory(robot, q, dq, ddq, structural=panda_structural)
    Y_static = regressor(robot, q, dq, ddq).reshape(-1, robot.n_parameters)
    expected = panda_structural.rank - _scaled_rank(Y_static)
    assert expected > 0
    assert len(result.unexcited) == expected
    assert result.unexcited_vectors.shape == (robot.n_parameters, expected)
    qg, dqg, ddqg = robot.random_states(30, seed=22)
    Y_moving = regressor(robot, qg, dqg, ddqg).reshape(-1, robot.n_parameters)
    for v in result.unexcited_vectors.T:
        assert np.linalg.norm(Y_static @ v) <= 1e-9 * np.linalg.norm(Y_static) * np.linalg.norm(v)
        assert np.linalg.norm(Y_moving @ v) > 1e-3 * np.linalg.norm(Y_moving) * np.linalg.norm(v)
    assert not np.any(result.unexcited_vectors[panda_structural.base.dependent])
    assert "not excited" in result.report()
    assert np.all(np.diff(result.information_eigenvalues) >= 0)
    assert result.information_eigenvalues[0] < 1e-12 * result.information_eigenvalues[-1]


# ------------------------------------------------------------ msd, view 1
M, C, K, B = 2.0, 0.8, 5.0, 1.5


def _simulate_msd(duration=20.0, rate=50.0):
    t = np.arange(0.0, duration, 1.0 / rate)

    def u_of(tt):
        return 1.2 * np.sin(1.1 * tt) + 0.7 * np.sin(2.3 * tt)

    sol = solve_ivp(
        lambda tt, x: [x[1], (B * u_of(tt) - C * x[1] - K * x[0]) / M],
        (t[0], t[-1]),
        [0.0, 0.0],
        t_eval=t,
        rtol=1e-11,
        atol=1e-12,
        method="DOP853",
    )
    y, dy = sol.y
    u = u_of(t)
    return t, y, dy, (B * u - C * dy - K * y) / M, u


def test_msd_structural_view():
    robot = get_robot("msd")
    result = analyze(robot)
    assert robot.n_parameters == 12
    assert result.rank == 3
    assert result.base.base_names == ["cart.m", "cart.fv", "cart.k"]
    assert result.base.expressions == ["cart.m", "cart.fv", "cart.k"]
    rotational = [
        f"cart.{p}" for p in ("mcx", "mcy", "mcz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
    ]
    assert result.unidentifiable == rotational
    text = result.report()
    assert "prismatic" in text and "never rotates" in text
    for name in rotational:
        assert name in text


def test_msd_view1_least_squares_recovers_m_c_k():
    robot = get_robot("msd")
    b = robot.settings["input_gain"]
    assert b == B
    _, y, dy, ddy, u = _simulate_msd()
    result = analyze_trajectory(robot, y[:, None], dy[:, None], ddy[:, None])
    assert result.rank == 3 and result.unexcited == []
    Y = regressor(robot, y[:, None], dy[:, None], ddy[:, None]).reshape(-1, 12)
    theta_base = np.linalg.lstsq(result.base.regressor(Y), b * u, rcond=None)[0]
    np.testing.assert_allclose(theta_base, [M, C, K], rtol=1e-8)
    assert any("never rotates" in n for n in result.notes)


# ------------------------------------------------------------ msd, view 2
def test_msd_view2_homogeneous_rank_3_null_space_along_rho():
    _, y, dy, ddy, u = _simulate_msd()
    result = analyze(np.column_stack([ddy, dy, y, -u]), names=["m", "c", "k", "b"])
    assert result.rank == 3
    assert result.null_space.shape == (4, 1)
    rho = np.array([M, C, K, B])
    n = result.null_space[:, 0]
    cos = abs(n @ rho) / (np.linalg.norm(n) * np.linalg.norm(rho))
    assert cos == pytest.approx(1.0, abs=1e-10)
    np.testing.assert_allclose(n / n[3] * B, rho, rtol=1e-8)
    assert len(result.unidentifiable) == 1


def test_msd_control_form_is_full_rank():
    _, y, dy, ddy, u = _simulate_msd()
    phi = np.column_stack([-y, -dy, u])
    result = analyze(phi, names=["k/m", "c/m", "b/m"])
    assert result.rank == 3 and result.unidentifiable == []
    assert result.null_space.shape == (3, 0)
    theta = np.linalg.lstsq(result.base.regressor(phi), ddy, rcond=None)[0]
    np.testing.assert_allclose(theta, [K / M, C / M, B / M], rtol=1e-8)


def test_textbook_rows_rank_one():
    result = analyze([[1.0, 0.0], [2.0, 0.0], [3.0, 0.0]], names=["theta1", "theta2"])
    assert result.rank == 1
    assert result.unidentifiable == ["theta2"]
    np.testing.assert_array_equal(result.null_space, [[0.0], [1.0]])
    assert result.base.expressions == ["theta1"]


def test_dependent_column_expression_and_to_base():
    # y3 = 2 y1 - 0.5 y2: theta_base = [t1 + 2 t3, t2 - 0.5 t3]
    rng = np.random.default_rng(0)
    Y = rng.standard_normal((20, 2))
    Y = np.column_stack([Y, 2 * Y[:, 0] - 0.5 * Y[:, 1]])
    result = analyze(Y, names=["a", "b", "c"])
    assert result.rank == 2
    np.testing.assert_allclose(result.base.K, [[2.0], [-0.5]], atol=1e-12)
    assert result.base.expressions == ["a + 2*c", "b - 0.5*c"]
    assert result.base.base_names == ["aR", "bR"]
    assert result.unidentifiable == ["c - 2*a + 0.5*b"]
    np.testing.assert_allclose(result.base.to_base([1.0, 1.0, 1.0]), [3.0, 0.5])
    theta = rng.standard_normal(3)
    np.testing.assert_allclose(Y @ theta, result.base.regressor(Y) @ result.base.to_base(theta))


def test_format_direction_leads_with_one_and_keeps_parameter_order():
    assert format_direction([1.0, -0.5, 1.0], ["a", "b", "c"], lead=0) == "a - 0.5*b + c"
    # the lead is scaled to 1: -a + 0.0841 b is the direction a - 0.0841 b
    assert format_direction([-1.0, 0.0841], ["a", "b"], lead=0) == "a - 0.0841*b"
    # default lead: the largest scaled entry; terms below 1e-6 of it are left out
    assert format_direction([0.5, -2.0, 1e-9], ["a", "b", "c"]) == "b - 0.25*a"
    assert format_direction([1.0, 1.0], ["a", "b"], scale=[1.0, 1e-7]) == "a"


def test_to_dict_is_json_ready(panda_structural):
    import json

    d = panda_structural.to_dict()
    text = json.dumps(d)
    assert json.loads(text)["rank"] == 43
    assert len(d["base_parameters"]) == 43 and {"name", "expression"} <= set(
        d["base_parameters"][0]
    )
    assert len(d["singular_values"]) == 70
    assert isinstance(panda_structural.base, BaseParameters)


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("Y", "names", "match"),
    [
        (np.zeros((0, 2)), ["a", "b"], "empty"),
        (np.zeros((5, 2)), ["a", "b"], "all zero"),
        ([[1.0, 2.0], [np.nan, 1.0], [3.0, 1.0]], ["a", "b"], r"nan at row 1, a"),
        ([[1.0, 2.0], [1.0, np.inf], [3.0, 1.0]], ["a", "b"], r"inf at row 1, b"),
        ([[1.0, 2.0, 3.0]], ["a", "b", "c"], "fewer rows than parameters"),
        ([[1.0, 2.0], [3.0, 4.0]], ["a", "b", "c"], "2 columns but 3 names"),
        ([[1.0, 2.0], [3.0, 4.0]], ["a", "a"], "unique"),
        ([1.0, 2.0], ["a", "b"], "dimensions"),
    ],
)
def test_bad_regressor_raises(Y, names, match):
    with pytest.raises(InputError, match=match):
        analyze(Y, names=names)


def test_nan_in_3d_regressor_names_sample_and_parameter():
    Y = np.ones((4, 2, 3))
    Y[2, 1, 0] = np.nan
    with pytest.raises(InputError, match="sample 2, joint row 1, x"):
        analyze(Y, names=["x", "y", "z"])


def test_missing_names_and_bad_tolerance():
    with pytest.raises(InputError, match="names"):
        analyze(np.eye(3))
    with pytest.raises(InputError, match="tolerance"):
        analyze(np.eye(3), names=["a", "b", "c"], tolerance=2.0)
    robot = get_robot("ur5")
    with pytest.raises(InputError, match="robot.n_parameters"):
        analyze(np.eye(3), robot=robot)
    with pytest.raises(InputError, match="samples"):
        structural_analysis(robot, n_samples=2)


@pytest.mark.parametrize(
    ("A", "match"),
    [
        (np.ones((2, 3)), "square"),
        ([[1.0, 2.0], [0.0, 1.0]], "symmetric"),
        ([[1.0, 0.0], [0.0, -1.0]], "negative diagonal"),
        ([[1.0, 2.0], [2.0, 1.0]], "positive semi-definite"),
        ([[1.0, np.nan], [np.nan, 1.0]], "nan at"),
    ],
)
def test_bad_information_matrix(A, match):
    with pytest.raises(InputError, match=match):
        analyze_information(A, ["a", "b"], n_rows=10)


def test_information_needs_enough_rows():
    with pytest.raises(InputError, match="fewer rows"):
        analyze_information(np.eye(3), ["a", "b", "c"], n_rows=2)


def test_raise_if_deficient_names_the_directions():
    from manip_id import RankDeficiencyError

    result = analyze([[1.0, 0.0], [2.0, 0.0], [3.0, 0.0]], names=["theta1", "theta2"])
    with pytest.raises(RankDeficiencyError, match="theta2") as info:
        result.raise_if_deficient()
    assert info.value.rank == 1 and info.value.n_columns == 2
    assert info.value.directions == ["theta2"]
    analyze(np.eye(2), names=["a", "b"]).raise_if_deficient()  # full rank: no error


def test_tolerance_floor_treats_rounding_size_columns_as_zero():
    """A column 1e-10 the size of the others (URDF rounding) is not identifiable by default."""
    rng = np.random.default_rng(1)
    Y = rng.standard_normal((50, 3))
    Y[:, 2] *= 1e-10
    default = analyze(Y, names=["a", "b", "c"])
    assert default.tolerance == pytest.approx(1e-8)
    assert default.rank == 2 and default.unidentifiable == ["c"]
    strict = analyze(Y, names=["a", "b", "c"], tolerance=1e-13)
    assert strict.rank == 3 and strict.unidentifiable == []
