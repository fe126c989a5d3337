"""Payload and drive-gain warnings point at the user's call, from whichever step warns."""

from __future__ import annotations

import warnings

import numpy as np
from conftest import get_robot
from test_payload import make_payload, make_runs

from manip_id.payload import PayloadWarning, identify_drive_gains, identify_payload


def _caught(func):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        func()
    return [w for w in caught if issubclass(w.category, PayloadWarning)]


def test_payload_warning_points_at_the_caller():
    pendulum = get_robot("double_pendulum")
    u, ld = make_runs(pendulum, "link2", make_payload(), n=300, noise=0.01)
    caught = _caught(lambda: identify_payload(pendulum, u, ld, "link2"))
    assert caught and all(w.filename == __file__ for w in caught), [w.filename for w in caught]
    assert any("not identifiable" in str(w.message) for w in caught)


def test_drive_gain_warnings_point_at_the_caller():
    ur5 = get_robot("ur5")
    gains = np.array([0.45, 0.8, 1.1, 1.4, 1.7, 2.3])  # [N m / A]
    u, ld = make_runs(ur5, "tool0", make_payload(), n=300, gains=gains, still=(0,), seed=3)
    caught = _caught(lambda: identify_drive_gains(ur5, u, ld, "tool0", 1.3, method="tls"))
    texts = [str(w.message) for w in caught]
    assert any("unexcited" in t for t in texts) and any("TLS needs" in t for t in texts)
    assert all(w.filename == __file__ for w in caught), [w.filename for w in caught]


def test_negative_gain_warning_points_at_the_caller():
    ur5 = get_robot("ur5")
    gains = np.array([-0.45, 0.8, 1.1, 1.4, 1.7, 2.3])  # [N m / A]: joint 0's sign flipped
    u, ld = make_runs(ur5, "tool0", make_payload(), n=300, gains=gains, seed=4)
    caught = _caught(lambda: identify_drive_gains(ur5, u, ld, "tool0", 1.3, method="ols"))
    neg = [w for w in caught if "came out <= 0" in str(w.message)]
    assert len(neg) == 1 and ur5.dof_names[0] in str(neg[0].message)
    assert neg[0].filename == __file__, neg[0].filename
