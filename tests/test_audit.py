"""The log auditor on synthetic logs with one known defect each, and on the real Panda log.

The logs are made with numpy and Pinocchio alone (tests/_logs.py): noise-free
excitations of the UR5 with viscous and Coulomb friction. Each defect is put in
by hand; the audit must name it with the right joint and value, and the
identification after the option it suggests must equal the clean one.
"""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest
from _logs import log, save_npz
from conftest import get_robot

from manip_id.audit import EXPLAINED_MIN, AuditOptions, audit_file, audit_files
from manip_id.cli import main
from manip_id.datasets import FileSpec, Window
from manip_id.errors import DataError
from manip_id.identification import FileOptions, PreprocessOptions, identify, scan_file

RATE = 200.0  # [Hz]
GAINS = np.array([0.1, 0.15, 0.2, 0.25, 0.3, 0.12])  # measured / true torque (currents)


@pytest.fixture(scope="module")
def robot():
    return get_robot("ur5", friction="viscous,coulomb")


@pytest.fixture(scope="module")
def clean(robot):
    return log(robot, n=1500, rate=RATE, seed=3)


def _estimate(robot, specs, **options):
    return identify(
        robot, specs, files=FileOptions(preprocess=PreprocessOptions(**options), audit=False)
    ).estimate


def _close(a, b, tol=1e-8):
    np.testing.assert_allclose(a, b, rtol=tol, atol=tol * np.abs(b).max())


def _gravity(robot, q):
    model = robot.model
    data = model.createData()
    return np.array([pin.computeGeneralizedGravity(model, data, qk) for qk in q])


def test_clean_log_has_no_finding(robot, clean, tmp_path):
    path = save_npz(tmp_path / "clean.npz", robot, *clean)
    fa = audit_file(robot, path)
    assert fa.findings == [] and not fa.static and fa.rate == pytest.approx(RATE)
    for j in fa.joints:
        assert j.scale == pytest.approx(1.0, abs=0.02)
        assert abs(j.delay) < 1.0 / RATE and abs(j.offset) < 0.05


def test_currents_scale_per_joint(robot, clean, tmp_path):
    t, q, dq, ddq, tau = clean
    path = save_npz(tmp_path / "currents.npz", robot, t, q, dq, ddq, tau * GAINS)
    fa = audit_file(robot, path)
    np.testing.assert_allclose([j.scale for j in fa.joints], GAINS, rtol=0.05)
    text = "\n".join(fa.findings)
    for name in robot.dof_names:
        assert f"joint {name}: measured / nominal torque" in text
    assert "currents or a gear ratio" in text and "try --torque-scale" in text
    np.testing.assert_allclose(fa.suggestions["torque_scale"], 1 / GAINS, rtol=0.05)
    ref = _estimate(robot, [save_npz(tmp_path / "c.npz", robot, *clean)])
    _close(_estimate(robot, [path], torque_scale=tuple(1 / GAINS)), ref)


def test_flipped_sign(robot, clean, tmp_path):
    t, q, dq, ddq, tau = clean
    bad = tau.copy()
    bad[:, 2] *= -1
    path = save_npz(tmp_path / "sign.npz", robot, t, q, dq, ddq, bad)
    fa = audit_file(robot, path)
    assert fa.joints[2].scale == pytest.approx(-1.0, rel=0.05)
    assert [f for f in fa.findings if f.startswith("sign flipped")] == [
        f"sign flipped on joint elbow_joint (measured / nominal torque {fa.joints[2].scale:.3g})"
    ]
    gains = np.array(fa.suggestions["torque_scale"])
    np.testing.assert_allclose(gains, [1, 1, -1, 1, 1, 1], rtol=0.05)
    ref = _estimate(robot, [save_npz(tmp_path / "c.npz", robot, *clean)])
    _close(_estimate(robot, [path], torque_scale=(1, 1, -1, 1, 1, 1)), ref)


def test_delay_25_ms(robot, tmp_path):
    lag = 5  # 25 ms at 200 Hz
    t, q, dq, ddq, tau = log(robot, n=1500 + lag, rate=RATE, seed=3)
    # row k of the file: the motion of sample k + lag, the torque of sample k
    path = save_npz(tmp_path / "late.npz", robot, t[lag:], q[lag:], dq[lag:], ddq[lag:], tau[:-lag])
    fa = audit_file(robot, path)
    assert fa.joints[0].delay == pytest.approx(0.025, abs=1.0 / RATE)
    assert all(j.delay == fa.joints[0].delay for j in fa.joints)
    assert any("the torque stream lags the motion stream by" in f for f in fa.findings)
    assert fa.suggestions["delay"] == pytest.approx(0.025, abs=1.0 / RATE)
    # --delay 0.025: file rows 0 .. N-lag-1 with the torque of their own motion
    fixed = _estimate(robot, [FileSpec(path, delay=0.025)])
    ref_path = save_npz(
        tmp_path / "ref.npz",
        robot,
        t[lag:-lag],
        q[lag:-lag],
        dq[lag:-lag],
        ddq[lag:-lag],
        tau[lag:-lag],
    )
    _close(fixed, _estimate(robot, [ref_path]))
    after = audit_file(robot, FileSpec(path, delay=0.025))
    assert not any("lags" in f for f in after.findings)


def test_time_in_nanoseconds(robot, clean, tmp_path):
    t, q, dq, ddq, tau = clean
    path = save_npz(tmp_path / "ns.npz", robot, 1.7e18 + t * 1e9, q, dq, ddq, tau)
    with pytest.raises(DataError, match=r"stamps in ns\? pass --time-unit ns"):
        audit_file(robot, path)
    small = save_npz(tmp_path / "ns0.npz", robot, t * 1e9, q, dq, ddq, tau)
    with pytest.raises(DataError, match=r"rate of 2e-07 Hz.*--time-unit ns"):
        audit_file(robot, small)
    fa = audit_file(robot, FileSpec(path, time_unit="ns"))
    assert fa.rate == pytest.approx(RATE, rel=1e-4) and fa.findings == []  # 256 ns steps
    ref = _estimate(robot, [save_npz(tmp_path / "c.npz", robot, *clean)])
    _close(_estimate(robot, [FileSpec(small, time_unit="ns")]), ref)


def test_standstill_edges(robot, clean, tmp_path):
    t, q, dq, ddq, tau = clean
    rest = int(3 * RATE)
    q_a, q_b = np.repeat(q[:1], rest, axis=0), np.repeat(q[-1:], rest, axis=0)
    zeros = np.zeros((rest, robot.nv))
    tt = np.arange(t.size + 2 * rest) / RATE
    qq = np.vstack([q_a, q, q_b])
    dd = np.vstack([zeros, dq, zeros])
    aa = np.vstack([zeros, ddq, zeros])
    ta = np.vstack([_gravity(robot, q_a), tau, _gravity(robot, q_b)])
    path = save_npz(tmp_path / "edges.npz", robot, tt, qq, dd, aa, ta)
    fa = audit_file(robot, path)
    assert fa.rest == pytest.approx((3.0, 3.0), abs=1.0 / RATE)
    assert any("--trim-standstill keeps" in f for f in fa.findings)
    assert fa.suggestions["trim_standstill"] is True
    assert fa.kept == Window(3.0, tt[rest + t.size - 1] + 0.5 / RATE, "s")
    audit = audit_files(robot, [path])
    trimmed = audit.trimmed()
    ref_path = save_npz(tmp_path / "moving.npz", robot, tt[rest:-rest], q, dq, ddq, tau)
    _close(_estimate(robot, trimmed), _estimate(robot, [ref_path]))
    assert scan_file(robot, trimmed[0]).quality.n_samples == t.size


def test_implausible_rows_dropped(robot, clean, tmp_path):
    t, q, dq, ddq, tau = clean
    rng = np.random.default_rng(0)
    rows = np.sort(rng.choice(t.size, 50, replace=False))
    bad = tau.copy()
    bad[rows, rng.integers(0, robot.nv, 50)] = 1e184 * rng.uniform(0.5, 2, 50)
    path = save_npz(tmp_path / "wild.npz", robot, t, q, dq, ddq, bad)
    with pytest.raises(DataError, match="beyond any plausible value"):
        scan_file(robot, path)
    quality = scan_file(robot, path, PreprocessOptions(drop_bad_rows=True)).quality
    assert quality.n_dropped == 50 and quality.dropped == {"implausible": 50}
    assert quality.first_dropped == rows[0]
    assert quality.to_dict()["dropped"] == {"implausible": 50}
    fa = audit_file(robot, path, AuditOptions(drop_bad_rows=True))
    assert fa.dropped == {"implausible": 50}
    assert fa.findings[0] == f"50 bad rows dropped (50 implausible; first row {rows[0]})"
    keep = np.setdiff1d(np.arange(t.size), rows)
    ref = save_npz(tmp_path / "kept.npz", robot, t[keep], q[keep], dq[keep], ddq[keep], tau[keep])
    _close(_estimate(robot, [path], drop_bad_rows=True), _estimate(robot, [ref]))


def test_truncated_last_line(robot, clean, tmp_path):
    t, q, dq, ddq, tau = clean
    names = robot.dof_names
    head = ["t", *(f"q_{n}" for n in names), *(f"dq_{n}" for n in names)]
    head += [f"tau_{n}" for n in names] + [f"ddq_{n}" for n in names]
    table = np.column_stack([t, q, dq, tau, ddq])
    lines = [",".join(head)] + [",".join(repr(float(x)) for x in row) for row in table]
    cut = lines[-1][: len(lines[-1]) // 2].rsplit(",", 1)[0]  # a write stopped mid-row
    path = tmp_path / "cut.csv"
    path.write_text("\n".join(lines[:-1] + [cut]) + "\n")
    with pytest.raises(DataError, match=f"line {len(lines)} has .* cells but line 2 has"):
        scan_file(robot, path)
    quality = scan_file(robot, path, PreprocessOptions(drop_bad_rows=True)).quality
    assert quality.dropped == {"malformed line": 1} and quality.first_dropped == t.size - 1
    assert "1 malformed line" in quality.text()
    ref = save_npz(tmp_path / "ref.npz", robot, t[:-1], q[:-1], dq[:-1], ddq[:-1], tau[:-1])
    _close(_estimate(robot, [path], drop_bad_rows=True), _estimate(robot, [ref]))


def test_wrong_field_count_in_the_middle(robot, clean, tmp_path):
    t, q, dq, ddq, tau = clean
    from manip_id.datasets import Dataset, save_dataset

    path = save_dataset(Dataset(t, q, dq, tau, ddq, tuple(robot.dof_names)), tmp_path / "a.csv")
    lines = path.read_text().splitlines()
    lines[101] += ",0.5"  # data row 100: one cell too many
    path.write_text("\n".join(lines) + "\n")
    quality = scan_file(robot, path, PreprocessOptions(drop_bad_rows=True)).quality
    assert quality.dropped == {"malformed line": 1} and quality.first_dropped == 100


def test_static_file(robot, tmp_path):
    rng = np.random.default_rng(1)
    n, res = 2000, 1e-4  # an encoder of 1e-4 rad
    q0 = np.array([0.3, -1.2, 1.0, -0.5, 0.8, 0.1])
    q = q0 + res * rng.integers(-1, 2, (n, robot.nv))  # quantization noise only
    dq = 2e-3 * rng.standard_normal((n, robot.nv))  # velocity noise [rad/s]
    tau = _gravity(robot, q) + 0.3
    t = np.arange(n) / RATE
    path = save_npz(tmp_path / "static.npz", robot, t, q, dq, np.zeros_like(dq), tau)
    quality = scan_file(robot, path).quality
    assert quality.static and quality.warnings == []
    np.testing.assert_allclose(quality.resolution, res, rtol=1e-6)
    fa = audit_file(robot, path)
    assert fa.static and fa.findings == ["static: used for gravity and offset only"]
    assert all(j.scale is None and j.delay is None for j in fa.joints)
    np.testing.assert_allclose([j.offset for j in fa.joints], 0.3, atol=1e-3)


def test_positions_in_degrees_and_wrapped(robot, clean, tmp_path):
    t, q, dq, ddq, tau = clean
    deg = q.copy()
    deg[:, 1] = np.degrees(q[:, 1])
    fa = audit_file(robot, save_npz(tmp_path / "deg.npz", robot, t, deg, dq, ddq, tau))
    assert any(f.startswith("joint shoulder_lift_joint: positions reach") for f in fa.findings)
    wrapped = q.copy()
    wrapped[:, 0] = np.angle(np.exp(1j * (q[:, 0] + 3.0)))  # crosses +-pi
    fa = audit_file(robot, save_npz(tmp_path / "wrap.npz", robot, t, wrapped, dq, ddq, tau))
    assert any("shoulder_pan_joint: positions jump by about 2 pi" in f for f in fa.findings)


def test_cli_audit_and_identify_options(robot, clean, tmp_path, capsys):
    t, q, dq, ddq, tau = clean
    rest = int(3 * RATE)
    zeros = np.zeros((rest, robot.nv))
    q_a = np.repeat(q[:1], rest, axis=0)
    path = save_npz(
        tmp_path / "e.npz",
        robot,
        np.arange(t.size + rest) / RATE,
        np.vstack([q_a, q]),
        np.vstack([zeros, dq]),
        np.vstack([zeros, ddq]),
        np.vstack([_gravity(robot, q_a), tau]) * GAINS,
    )
    out = tmp_path / "audit.json"
    assert main(["audit", "ur5", "--data", str(path), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "audit against the nominal model of ur5" in text and "try --torque-scale" in text
    doc = json.loads(out.read_text())["audit"]
    joint = doc["files"][0]["joints"][0]
    assert set(joint) >= {"joint", "scale", "delay", "offset", "standstill"}
    assert joint["scale"] == pytest.approx(GAINS[0], rel=0.05)
    gains = ",".join(repr(float(1 / g)) for g in GAINS)
    res = tmp_path / "id.json"
    args = ["identify", "ur5", "--friction", "viscous,coulomb", "--data", str(path)]
    args += ["--torque-scale", gains, "--trim-standstill", "--json", str(res)]
    assert main(args) == 0
    doc = json.loads(res.read_text())
    assert doc["audit"]["files"][0]["kept_window"] == "3:10.4975"
    assert doc["files"][0]["window"] == "3:10.4975"
    assert doc["files"][0]["n_samples"] == t.size
    assert not [f for f in doc["audit"]["files"][0]["findings"] if "torque" in f]
    capsys.readouterr()
    bad = ["identify", "ur5", "--simulate", "--delay", "0.01"]
    assert main(bad) == 2
    assert "--delay applies to --data files" in capsys.readouterr().err


def test_real_panda_log(panda_log):
    robot = get_robot("panda")
    fa = audit_file(robot, panda_log)
    step = 1.0 / fa.rate
    assert fa.findings == []
    # no delay worth the name: within two samples, and aligning removes < 5 % of the
    # held-out error (the estimate moves between 0.5 and 1.6 samples with the cut-off)
    assert fa.delay_gain < 0.05
    for j in fa.joints:
        assert abs(j.delay) <= 2 * step
        if j.scale is None:  # the nominal model does not explain this joint's torque
            assert j.explained < EXPLAINED_MIN
        else:
            assert 0.5 < j.scale < 2.0


def test_cli_time_unit_and_delay(robot, clean, tmp_path, capsys):
    t, q, dq, ddq, tau = clean
    path = save_npz(tmp_path / "ns.npz", robot, t * 1e9, q, dq, ddq, tau)
    args = ["identify", "ur5", "--friction", "viscous,coulomb", "--data", str(path)]
    assert main(args) == 2
    assert "stamps in ns? pass --time-unit ns" in capsys.readouterr().err
    res = tmp_path / "r.json"
    assert main([*args, "--time-unit", "ns", "--delay", "0", "--json", str(res)]) == 0
    doc = json.loads(res.read_text())
    assert doc["audit"]["files"][0]["rate"] == pytest.approx(RATE)
    assert doc["n_samples"] == t.size


def test_payload_and_drive_gains_run_the_audit(tmp_path, capsys):
    from test_payload import make_payload, make_runs

    ur5 = get_robot("ur5")
    gains = np.array([0.45, 0.8, 1.1, 1.4, 1.7, 2.3])  # [N m / A]
    payload = make_payload()

    def save(name, block):
        q, dq, ddq, tau = block
        t = 0.01 * np.arange(q.shape[0])
        return save_npz(tmp_path / name, ur5, t, q, dq, ddq, tau)

    runs = make_runs(ur5, "tool0", payload, n=500)
    u, ld = save("u.npz", runs[0]), save("l.npz", runs[1])
    cu, cl = make_runs(ur5, "tool0", payload, n=500, seed=3, gains=gains)
    cu, cl = save("cu.npz", cu), save("cl.npz", cl)
    out = tmp_path / "p.json"
    args = ["payload", "ur5", "--unloaded", str(u), "--loaded", str(ld), "--frame", "tool0"]
    assert main([*args, "--json", str(out)]) == 0
    assert "audit against the nominal model of ur5" in capsys.readouterr().out
    doc = json.loads(out.read_text())
    assert [f["file"] for f in doc["audit"]["files"]] == [str(u), str(ld)]
    assert doc["audit"]["files"][0]["findings"] == []
    out = tmp_path / "g.json"
    args = ["drive-gains", "ur5", "--unloaded", str(cu), "--loaded", str(cl), "--frame", "tool0"]
    args += ["--payload-mass", str(payload.mass), "--json", str(out)]
    assert main(args) == 0
    doc = json.loads(out.read_text())
    unloaded = doc["audit"]["files"][0]
    # the currents are tau / G: the audit reads their scale and suggests nothing
    np.testing.assert_allclose([j["scale"] for j in unloaded["joints"]], 1 / gains, rtol=0.05)
    assert "torque_scale" not in unloaded["suggestions"]


def test_position_offset_against_the_limits(robot, clean, tmp_path):
    t, q, dq, ddq, tau = clean
    shifted = q.copy()
    lo, hi = robot.lower[2], robot.upper[2]  # elbow_joint: [-pi, pi]
    shifted[:, 2] = q[:, 2] - q[:, 2].min() + hi - 0.5 * (q[:, 2].max() - q[:, 2].min()) + 1.0
    span = q[:, 2].max() - q[:, 2].min()
    assert shifted[:, 2].max() > hi + 0.05 * (hi - lo) and span < hi - lo
    fa = audit_file(robot, save_npz(tmp_path / "off.npz", robot, t, shifted, dq, ddq, tau))
    found = [f for f in fa.findings if f.startswith("joint elbow_joint: positions")]
    assert len(found) == 1 and "while their span fits: a zero offset?" in found[0]
    assert f"(adding {hi - shifted[:, 2].max():+.3g} rad brings them inside)" in found[0]
