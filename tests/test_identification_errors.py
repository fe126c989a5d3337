"""Error figures whose meaning does not change with an option; "not determined" parameters.

References are independent of the accumulated sums: torques from Pinocchio's ``rnea``
plus friction in numpy, predictions by :meth:`IdentificationResult.predict` (the
regressor) and norms in numpy on the arrays of the files.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot

from manip_id.identification import (
    NOT_DETERMINED,
    FileOptions,
    PreprocessOptions,
    identify,
    iter_processed,
    scan_file,
)

FV, FC = 0.3, 0.8  # viscous [N m s/rad], Coulomb [N m]
DQ_NOISE = 0.002  # measured velocity noise [rad/s]
EPS = 0.02  # velocity deadband [rad/s], 10x the velocity noise


@pytest.fixture(scope="module")
def robot():
    return get_robot("double_pendulum", friction=("viscous", "coulomb"))


def _stop_and_go(robot, seed: int, n: int = 3000, dt: float = 0.005):
    """Moves separated by standstills: q(t) = q0 + A s(t) sin-shaped, s flat half the time.

    The true velocity is exactly zero at standstill, so the true Coulomb torque
    ``FC sign(dq)`` is zero there; the logged velocity carries noise.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    phase = (t % 2.0) / 2.0  # 2 s cycles: 1 s move, 1 s still
    moving = phase < 0.5
    u = np.where(moving, phase / 0.5, 1.0)  # 0 -> 1 during the move
    amp = rng.uniform(0.5, 1.2, robot.nv) * rng.choice([-1, 1], robot.nv)
    cycle = np.floor(t / 2.0)
    sign = np.where(cycle % 2 == 0, 1.0, -1.0)[:, None]  # back and forth
    s = 0.5 * (1 - np.cos(np.pi * u))  # smooth 0 -> 1
    ds = np.where(moving, 0.5 * np.pi * np.sin(np.pi * u) / 1.0, 0.0)  # [1/s]
    dds = np.where(moving, 0.5 * np.pi**2 * np.cos(np.pi * u) / 1.0, 0.0)
    base = np.where(cycle % 2 == 0, 0.0, 1.0)[:, None]
    q = amp * (base + sign * s[:, None])
    dq = amp * sign * ds[:, None]
    ddq = amp * sign * dds[:, None]
    tau = np.array([pin.rnea(robot.model, robot.data, *x) for x in zip(q, dq, ddq, strict=True)])
    tau += FV * dq + FC * np.sign(dq)  # sign(0) = 0 at standstill
    tau += 0.01 * rng.standard_normal(tau.shape)  # [N m]
    dq_log = dq + DQ_NOISE * rng.standard_normal(dq.shape)
    return dict(t=t, q=q, dq=dq_log, ddq=ddq, tau=tau)


@pytest.fixture(scope="module")
def files(robot, tmp_path_factory):
    folder = tmp_path_factory.mktemp("stopgo")
    out = []
    for k in range(2):
        arrays = _stop_and_go(robot, seed=k)
        np.savez(folder / f"stopgo{k}.npz", **arrays)
        out.append((str(folder / f"stopgo{k}.npz"), arrays))
    return out


def _deadband_prediction(res, robot, a, eps):
    """``Y_b theta`` with the Coulomb term removed where ``|dq_j| < eps`` (numpy)."""
    pred = res.predict(robot, a["q"], a["dq"], a["ddq"])
    for j, dof in enumerate(robot.dof_names):
        fc = res.estimate[res.names.index(f"{dof}.fc")]
        still = np.abs(a["dq"][:, j]) < eps
        pred[still, j] -= fc * np.sign(a["dq"][still, j])
    return pred


def test_all_rows_error_with_a_deadband_is_no_worse_on_stop_and_go_data(robot, files):
    (train, _), (valid, va) = files
    plain = identify(robot, [train], validation=[valid], files=FileOptions(audit=False))
    opts = PreprocessOptions(velocity_deadband=EPS)
    band = identify(
        robot, [train], validation=[valid], files=FileOptions(preprocess=opts, audit=False)
    )
    re0, re1 = plain.relative_error, band.relative_error
    # the all-rows errors are comparable: the deadband fit is no worse there
    assert re1.validation <= re0.validation
    assert re1.train <= re0.train * 1.01
    assert re0.validation_moving is None and re1.validation_moving is not None
    # all rows, the standstill rows predicted with the deadband: numpy on the file's arrays
    pred = _deadband_prediction(band, robot, va, EPS)
    expected = np.linalg.norm(va["tau"] - pred) / np.linalg.norm(va["tau"])
    assert re1.validation == pytest.approx(expected, rel=1e-6)
    moving = np.abs(va["dq"]) >= EPS
    err = np.where(moving, va["tau"] - band.predict(robot, va["q"], va["dq"], va["ddq"]), 0.0)
    expected_moving = np.linalg.norm(err) / np.linalg.norm(np.where(moving, va["tau"], 0.0))
    assert re1.validation_moving == pytest.approx(expected_moving, rel=1e-6)
    # without a deadband the plain error is over all rows, sign(dq) as logged
    pred0 = plain.predict(robot, va["q"], va["dq"], va["ddq"])
    assert re0.validation == pytest.approx(
        np.linalg.norm(va["tau"] - pred0) / np.linalg.norm(va["tau"]), rel=1e-6
    )
    # the fleet path reports the same
    fleet = identify(
        robot, [train], validation=[valid], files=FileOptions(preprocess=opts, audit=False)
    ).to_dict()
    local = band.to_dict()
    fleet.pop("timings"), local.pop("timings")
    assert fleet == local and "validation_moving" in fleet["relative_error"]


def _raw_reference(robot, path, arrays, options, res):
    """``||tau_raw - Y_b theta|| / ||tau_raw||`` on the processed samples (numpy)."""
    scan = scan_file(robot, path, options)
    _, blocks = iter_processed(robot, path, options, scan)
    rows = np.vstack(list(blocks))
    nq, nv = robot.nq, robot.nv
    t, q, dq = rows[:, 0], rows[:, 1 : 1 + nq], rows[:, 1 + nq : 1 + nq + nv]
    ddq = rows[:, 1 + nq + 2 * nv :]
    raw = np.column_stack([np.interp(t, arrays["t"], arrays["tau"][:, j]) for j in range(nv)])
    pred = res.predict(robot, q, dq, ddq)
    return np.linalg.norm(raw - pred) / np.linalg.norm(raw)


def test_errors_against_the_raw_torques_for_one_and_several_files(robot, files, tmp_path):
    paths = []
    for k, (_, a) in enumerate(files):  # the same logs without accelerations: filtered
        p = tmp_path / f"noddq{k}.npz"
        np.savez(p, t=a["t"], q=a["q"], dq=a["dq"], tau=a["tau"])
        paths.append(str(p))
    opts = PreprocessOptions(cutoff=10.0)
    one = identify(robot, paths[:1], files=FileOptions(preprocess=opts, audit=False))
    raw = one.to_dict()["relative_error_raw"]
    assert raw["train"] == pytest.approx(
        _raw_reference(robot, paths[0], files[0][1], opts, one), rel=1e-6
    )
    # the filtered torques fit better than the raw ones (noise and the sign steps removed)
    assert raw["train"] > one.relative_error.train
    two = identify(
        robot, paths[:1], validation=paths[1:], files=FileOptions(preprocess=opts, audit=False)
    )
    raw2 = two.to_dict()["relative_error_raw"]
    assert raw2["validation"] == pytest.approx(
        _raw_reference(robot, paths[1], files[1][1], opts, two), rel=1e-6
    )
    assert raw2["nominal_validation"] is not None
    fleet = identify(
        robot, paths[:1], validation=paths[1:], files=FileOptions(preprocess=opts, audit=False)
    ).to_dict()
    assert fleet["relative_error_raw"] == raw2
    # unfiltered torques: nothing to compare against
    assert (
        "relative_error_raw"
        not in identify(robot, [files[0][0]], files=FileOptions(audit=False)).to_dict()
    )


def test_parameters_a_minimum_norm_solution_cannot_fix_are_not_shown_as_numbers():
    robot = get_robot("ur5")
    q, _, _ = robot.random_states(200, seed=3)  # postures at rest: gravity only
    dq = ddq = np.zeros((200, robot.nv))
    tau = np.array([pin.rnea(robot.model, robot.data, *x) for x in zip(q, dq, ddq, strict=True)])
    res = identify(robot, (q, dq, ddq, tau), minimum_norm=True)
    doc = res.to_dict()
    undetermined = [p for p in doc["base_parameters"] if NOT_DETERMINED in p["flags"]]
    assert 0 < len(undetermined) < len(doc["base_parameters"])
    text = res.table()
    for p in undetermined:
        line = next(ln for ln in text.splitlines() if ln.startswith(p["name"] + " "))
        assert line.split()[1:4] == ["not", "determined", "-"]  # no value, no std
    assert any("not determined by these data" in w for w in doc["warnings"])
