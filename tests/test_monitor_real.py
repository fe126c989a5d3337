"""The monitor on the real Panda log (Gaz et al. 2019): quiet on new data, a 2 N m hit found.

The log is identified as ``manip-id identify --split 0.7`` does (viscous, Coulomb and
offset friction); the bounds are calibrated on the training part (raw signals, the
observer's defaults; the log is one run, so the calibration is in-sample and says so),
then the validation part must raise no alarm, and the validation part with 2 N m added
to joint 4 for 0.5 s (at three places) must be detected each time.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from manip_id import load_robot
from manip_id.cli import main
from manip_id.errors import MonitorWarning
from manip_id.monitor import CollisionMonitor, calibrate_thresholds, load_model, read_log

DELAY = 0.1  # stated detection delay [s]


@pytest.fixture(scope="module")
def panda_setup(panda_log, tmp_path_factory):
    out = tmp_path_factory.mktemp("panda_monitor") / "panda.json"
    argv = ["identify", "panda", "--data", str(panda_log), "--friction", "viscous,coulomb,offset"]
    assert main([*argv, "--split", "0.7", "--json", str(out)]) == 0
    split = float(json.loads(out.read_text())["files"][0]["window"].lstrip(":"))
    robot = load_robot("panda", friction="viscous,coulomb,offset")
    model = load_model(robot, out)
    train = read_log(robot, f"{panda_log}@:{split}")
    valid = read_log(robot, f"{panda_log}@{split}:")
    with pytest.warns(MonitorWarning, match="training data"):
        th = calibrate_thresholds(robot, model, [train])
    assert th.in_sample == [train.file]
    return robot, model, th, valid


def test_no_alarm_on_the_validation_part(panda_setup):
    robot, model, th, valid = panda_setup
    assert th.rate == 0.0 and th.n_samples > 14000
    run = CollisionMonitor(robot, model, th).run(valid.t, valid.q, valid.dq, valid.tau)
    assert run.detections() == []
    assert np.abs(run.residual).max() > 0.1  # the residual is not trivially zero


@pytest.mark.parametrize("offset", [0.5, 2.5, 4.5])
def test_two_newton_metres_on_joint_4_are_detected(panda_setup, offset):
    robot, model, th, valid = panda_setup
    start = valid.t[0] + offset
    tau = valid.tau.copy()
    on = (valid.t >= start) & (valid.t < start + 0.5)
    tau[on, 3] -= 2.0  # [N m]: an external torque of +2 N m on panda_joint4
    run = CollisionMonitor(robot, model, th).run(valid.t, valid.q, valid.dq, tau)
    dets = run.detections()
    assert len(dets) == 1, [d.to_dict() for d in dets]
    assert dets[0].joints == ["panda_joint4"]
    assert start <= dets[0].start <= start + DELAY
    assert dets[0].peak == pytest.approx(2.0, abs=0.4)
