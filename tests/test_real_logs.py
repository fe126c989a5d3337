"""Real-log workflow: several files, windows, torque scale, deadband, quality, CLI, bad input.

Logs are made here with numpy and Pinocchio (``_logs``): torques from
``pinocchio.rnea`` plus viscous and Coulomb friction, so the true base
parameters are known independently of manip_id.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from _logs import log, save_npz, truth
from conftest import get_robot

from manip_id.cli import main
from manip_id.datasets import Dataset, save_dataset
from manip_id.errors import DataError, InputError
from manip_id.identifiability import analyze
from manip_id.identification import (
    FileOptions,
    PreprocessOptions,
    RunOptions,
    accumulate_file,
    identify,
    scan_file,
)
from manip_id.signals import preprocess

ROBOT = ["ur5", "--friction", "viscous,coulomb"]


@pytest.fixture(scope="module")
def robot():
    return get_robot("ur5", friction="viscous,coulomb")


@pytest.fixture(scope="module")
def base(robot):
    return analyze(robot).base


@pytest.fixture()
def two_logs(robot, tmp_path):
    a = log(robot, n=1200, seed=1)
    b = log(robot, n=900, seed=2, t0=100.0)
    return (
        save_npz(tmp_path / "a.npz", robot, *a),
        save_npz(tmp_path / "b.npz", robot, *b),
        a,
        b,
    )


# ------------------------------------------------------------------ several files
def test_two_files_give_the_estimate_of_their_concatenation(robot, base, two_logs):
    pa, pb, a, b = two_logs
    res = identify(robot, [pa, pb], base=base, files=FileOptions(audit=False))
    assert res.n_samples == 1200 + 900
    cat = [np.concatenate([x, y]) for x, y in zip(a[1:], b[1:], strict=True)]
    ref = identify(robot, tuple(cat), base=base)  # the in-memory path on the concatenation
    scale = np.abs(ref.estimate).max()
    np.testing.assert_allclose(res.estimate, ref.estimate, rtol=0, atol=1e-9 * scale)
    beta = base.to_base(truth(robot))  # noise-free: the truth itself
    np.testing.assert_allclose(res.estimate, beta, rtol=0, atol=1e-7 * np.abs(beta).max())
    # one file alone is not the concatenation
    alone = identify(robot, [pa], base=base, files=FileOptions(audit=False))
    assert alone.n_samples == 1200


def test_pooled_and_per_file_validation(robot, base, two_logs, tmp_path):
    pa, pb, a, b = two_logs
    rng = np.random.default_rng(5)
    noisy = []
    for k, (t, q, dq, ddq, tau) in enumerate((a, b)):
        tau_n = tau + 0.05 * rng.standard_normal(tau.shape) * (1 + k)
        noisy.append(save_npz(tmp_path / f"v{k}.npz", robot, t, q, dq, ddq, tau_n))
    res = identify(robot, [pa], validation=noisy, base=base, files=FileOptions(audit=False))
    per = res.relative_error.validation_per_file
    assert [e["file"] for e in per] == [str(p) for p in noisy]
    sse = zz = 0.0
    for path, entry in zip(noisy, per, strict=True):  # independent: predictions and numpy
        z = np.load(path)
        pred = res.predict(robot, z["q"], z["dq"], z["ddq"])
        err = z["tau"] - pred
        assert entry["n_samples"] == z["t"].shape[0]
        assert entry["error"] == pytest.approx(np.linalg.norm(err) / np.linalg.norm(z["tau"]), 1e-6)
        for j, name in enumerate(robot.dof_names):
            want = np.linalg.norm(err[:, j]) / np.linalg.norm(z["tau"][:, j])
            assert entry["per_joint"][name] == pytest.approx(want, rel=1e-5)
        sse += (err**2).sum()
        zz += (z["tau"] ** 2).sum()
    assert res.relative_error.validation == pytest.approx(np.sqrt(sse / zz), rel=1e-6)


# ----------------------------------------------------------------------- windows
@pytest.mark.parametrize(
    ("window", "mask"),
    [
        ("1.5:4.25", lambda t, k: (t - t[0] >= 1.5) & (t - t[0] < 4.25)),
        (":2", lambda t, k: t - t[0] < 2),
        ("3:", lambda t, k: t - t[0] >= 3),
        ("#100:#700", lambda t, k: (k >= 100) & (k < 700)),
        ("#250:", lambda t, k: k >= 250),
    ],
)
def test_a_window_keeps_exactly_the_samples_inside_it(robot, base, two_logs, window, mask):
    pa, _, a, _ = two_logs
    t, q, dq, ddq, tau = a
    keep = mask(t, np.arange(t.shape[0]))
    fa = accumulate_file(robot, f"{pa}@{window}", None, base.independent)
    assert fa.n_samples == keep.sum()
    ref = identify(robot, (q[keep], dq[keep], ddq[keep], tau[keep]), base=base)
    acc = fa.accumulator
    np.testing.assert_allclose(acc.zz_joint, (tau[keep] ** 2).sum(axis=0), rtol=1e-12)
    res = identify(robot, [f"{pa}@{window}"], base=base, files=FileOptions(audit=False))
    np.testing.assert_allclose(
        res.estimate, ref.estimate, rtol=0, atol=1e-9 * np.abs(ref.estimate).max()
    )


def test_a_window_on_a_file_without_ddq_is_preprocessed_alone(robot, base, tmp_path):
    t, q, dq, ddq, tau = log(robot, n=4000, rate=500.0, seed=3)
    path = save_npz(tmp_path / "raw.npz", robot, t, q, dq, ddq, tau, with_ddq=False)
    keep = (t - t[0] >= 1.0) & (t - t[0] < 6.0)
    ref = preprocess(Dataset(t=t[keep], q=q[keep], dq=dq[keep], tau=tau[keep]), cutoff=8.0)
    fa = accumulate_file(robot, f"{path}@1:6", PreprocessOptions(cutoff=8.0), base.independent)
    assert fa.n_samples == ref.n_samples
    inmem = identify(robot, (ref.q, ref.dq, ref.ddq, ref.tau), base=base)
    res = identify(
        robot,
        [f"{path}@1:6"],
        base=base,
        files=FileOptions(preprocess=PreprocessOptions(cutoff=8.0), audit=False),
    )
    np.testing.assert_allclose(
        res.estimate, inmem.estimate, rtol=0, atol=1e-9 * np.abs(inmem.estimate).max()
    )


def test_window_errors(robot, two_logs):
    pa = two_logs[0]
    with pytest.raises(DataError, match=r"window @20:30 of .*a.npz holds no sample"):
        scan_file(robot, f"{pa}@20:30")
    with pytest.raises(DataError, match=r"starts after its 1200 samples"):
        scan_file(robot, f"{pa}@#5000:#6000")
    with pytest.raises(InputError, match="is empty"):
        scan_file(robot, f"{pa}@4:2")
    with pytest.raises(InputError, match="expected START:STOP"):
        scan_file(robot, f"{pa}@abc")
    with pytest.warns(UserWarning, match="ends after its 1200 samples"):
        scan_file(robot, f"{pa}@#1000:#5000")


# ------------------------------------------------------------------ torque scale
def test_currents_times_the_scale_give_the_torque_result(robot, base, two_logs, tmp_path):
    pa, _, a, _ = two_logs
    t, q, dq, ddq, tau = a
    gains = np.array([40.0, 55.0, 30.0, 8.0, 9.5, 7.0])  # [N m / A]
    cur = save_npz(tmp_path / "cur.npz", robot, t, q, dq, ddq, tau / gains)
    ref = identify(robot, [pa], base=base, files=FileOptions(audit=False))
    res = identify(
        robot,
        [cur],
        base=base,
        files=FileOptions(preprocess=PreprocessOptions(torque_scale=gains), audit=False),
    )
    np.testing.assert_allclose(
        res.estimate, ref.estimate, rtol=0, atol=1e-9 * np.abs(ref.estimate).max()
    )
    with pytest.raises(InputError, match=r"takes one value or one per joint \(6\), got 4"):
        identify(
            robot,
            [cur],
            files=FileOptions(preprocess=PreprocessOptions(torque_scale=(1, 2, 3, 4)), audit=False),
        )


# ----------------------------------------------------------------------- deadband
def test_deadband_rows_left_out_and_counted(robot, base, tmp_path):
    t, q, dq, ddq, tau = log(robot, n=1500, seed=4)
    eps = 0.05
    path = save_npz(tmp_path / "d.npz", robot, t, q, dq, ddq, tau)
    fa = accumulate_file(robot, path, PreprocessOptions(velocity_deadband=eps), base.independent)
    still = np.abs(dq) < eps
    np.testing.assert_array_equal(fa.excluded, still.sum(axis=0))
    assert still.sum() > 50  # the test data do cross zero velocity
    # the sums are those of the moving rows only (independent: the regressor times masks)
    from manip_id.robot.regressor import regressor

    Y = regressor(robot, q, dq, ddq)[:, :, base.independent]
    for j in range(robot.nv):
        m = ~still[:, j]
        np.testing.assert_allclose(
            fa.accumulator.b_joint[j], Y[m, j].T @ tau[m, j], rtol=1e-10, atol=1e-9
        )
        assert fa.accumulator.zz_joint[j] == pytest.approx((tau[m, j] ** 2).sum(), rel=1e-12)


# ------------------------------------------------------------------- quality
def test_quality_summary(robot, tmp_path):
    t, q, dq, ddq, tau = log(robot, n=2000, seed=6)
    t = t.copy()
    t[1000:] += 0.5  # one gap of 0.5 s
    q = q.copy()
    q[300:310, 2] = 3.4  # beyond elbow_joint's upper limit pi by 0.258
    tau = tau.copy()
    tau[:, 1] = np.clip(tau[:, 1], -5.0, 5.0)  # clipped torques on shoulder_lift_joint
    dq_bad = dq.copy()
    dq_bad[:, 4] *= 57.3  # degrees per second on wrist_2_joint
    path = save_npz(tmp_path / "q.npz", robot, t, q, dq_bad, ddq, tau)
    qual = scan_file(robot, path, PreprocessOptions(velocity_deadband=0.05)).quality
    assert qual.n_samples == 2000 and qual.n_gaps == 1
    assert qual.rate == pytest.approx(1999 / (t[-1] - t[0]))
    text = "\n".join(qual.warnings)
    assert "1 gaps in time" in text
    assert "joint elbow_joint: positions reach 3.4, 0.258 above its upper limit 3.142" in text
    assert "joint shoulder_lift_joint:" in text and "sit at the largest value 5" in text
    assert "joint wrist_2_joint: the integral of dq differs from the motion of q" in text
    # the velocity check, recomputed with scipy: q increments over 20 ms windows
    from scipy.integrate import cumulative_trapezoid

    m = int(round(0.02 / np.median(np.diff(t))))
    integral = cumulative_trapezoid(dq_bad, t, axis=0, initial=0)
    dqw, diw = np.diff(q[::m], axis=0), np.diff(integral[::m], axis=0)
    want = np.linalg.norm(dqw - diw, axis=0) / np.linalg.norm(diw, axis=0)
    # windows moving less than 10 encoder steps (here the smallest step of q, ~1e-7 rad,
    # near turning points) are left out: a few windows of negligible weight
    np.testing.assert_allclose(qual.velocity_mismatch, want, rtol=1e-6)
    clean = save_npz(tmp_path / "clean.npz", robot, *log(robot, n=2000, seed=6))
    good = scan_file(robot, clean).quality
    assert max(good.velocity_mismatch) < 1e-3 and not good.warnings
    share = np.mean(np.abs(dq_bad) < 0.05, axis=0)
    np.testing.assert_allclose(qual.standstill_share, share)
    d = qual.to_dict()
    assert d["standstill_share"]["wrist_3_joint"] == pytest.approx(share[5])
    json.dumps(d)


def test_nan_rows_refused_or_dropped(robot, base, tmp_path):
    t, q, dq, ddq, tau = log(robot, n=800, seed=7)
    tau = tau.copy()
    tau[123, 2] = np.nan
    tau[400, 0] = np.inf
    path = save_npz(tmp_path / "nan.npz", robot, t, q, dq, ddq, tau)
    with pytest.raises(DataError, match=r"nan.npz: tau holds nan at sample 123, elbow_joint"):
        scan_file(robot, path)
    fa = accumulate_file(robot, path, PreprocessOptions(drop_bad_rows=True), base.independent)
    assert fa.n_samples == 798
    assert fa.quality.n_dropped == 2 and fa.quality.first_dropped == 123
    keep = np.isfinite(tau).all(axis=1)
    np.testing.assert_allclose(fa.accumulator.zz_joint, (tau[keep] ** 2).sum(axis=0), rtol=1e-12)


def test_bad_file_in_a_list_is_named(robot, base, two_logs, tmp_path):
    pa, pb, a, _ = two_logs
    bad = tmp_path / "bad.npz"
    np.savez(bad, t=a[0], q=a[1][:, :3], dq=a[2][:, :3], tau=a[4][:, :3])  # another robot
    with pytest.raises(DataError, match=r"bad.npz: the data have 3 joints"):
        identify(robot, [pa, bad, pb], base=base, files=FileOptions(audit=False))
    with pytest.raises(DataError, match=r"no such data file or folder: .*missing.npz"):
        identify(robot, [pa, tmp_path / "missing.npz"], base=base, files=FileOptions(audit=False))


# ----------------------------------------------------------------------------- CLI
def _cli(args, tmp_path, capsys):
    out = tmp_path / "out.json"
    out.unlink(missing_ok=True)
    status = main(["identify", *ROBOT, *args, "--json", str(out)])
    cap = capsys.readouterr()
    return status, (json.loads(out.read_text()) if out.exists() else None), cap


def test_cli_several_files_both_spellings(two_logs, tmp_path, capsys):
    pa, pb = str(two_logs[0]), str(two_logs[1])
    s1, r1, cap = _cli(["--data", pa, pb], tmp_path, capsys)
    s2, r2, _ = _cli(["--data", pa, "--data", pb], tmp_path, capsys)
    assert s1 == s2 == 0
    assert r1["n_samples"] == r2["n_samples"] == 2100
    assert [q["file"] for q in r1["data_quality"]] == [pa, pb] == [f["file"] for f in r2["files"]]
    assert "data " + pa not in cap.out  # the quality summaries: in the JSON, printed with --verbose
    np.testing.assert_array_equal(
        [p["value"] for p in r1["base_parameters"]], [p["value"] for p in r2["base_parameters"]]
    )


def test_cli_windows_scale_deadband_validation(robot, two_logs, tmp_path, capsys):
    pa, pb, a, _ = two_logs
    t, q, dq, ddq, tau = a
    gains = [40.0, 55.0, 30.0, 8.0, 9.5, 7.0]
    cur = save_npz(tmp_path / "cur.npz", robot, t, q, dq, ddq, tau / np.array(gains))
    tb, qb, dqb, ddqb, taub = two_logs[3]
    curb = save_npz(tmp_path / "curb.npz", robot, tb, qb, dqb, ddqb, taub / np.array(gains))
    status, rep, cap = _cli(
        [
            "--data",
            f"{cur}@#0:#800",
            "--validate",
            f"{cur}@#800:",
            str(curb),
            "--torque-scale",
            ",".join(map(str, gains)),
            "--validate",
            f"{cur}@5:",
            "--velocity-deadband",
            "0.02",
        ],
        tmp_path,
        capsys,
    )
    assert status == 0, cap.err
    assert rep["torque_scale"] == gains
    assert rep["n_samples"] == 800
    per = rep["relative_error"]["validation_per_file"]
    assert [(e["file"], e["window"]) for e in per] == [
        (str(cur), "#800:"),
        (str(curb), None),
        (str(cur), "5:"),
    ]
    assert rep["n_validation_samples"] == 400 + 900 + int(np.sum(t - t[0] >= 5))
    left = rep["velocity_deadband"]["excluded_rows"]
    assert left == dict(
        zip(robot.dof_names, map(int, (np.abs(dq[:800]) < 0.02).sum(0)), strict=True)
    )
    # noise-free, right scale: exact on the moving rows; over all rows the standstill
    # rows are predicted with the deadband (no Coulomb term), the data have it
    assert rep["relative_error"]["validation_moving"] < 1e-6
    assert rep["relative_error"]["validation"] > rep["relative_error"]["validation_moving"]
    assert "rows left out per joint" in cap.out


def test_cli_window_option_and_split(two_logs, tmp_path, capsys):
    pa = str(two_logs[0])
    status, rep, _ = _cli(["--data", pa, "--window", "1:5", "--split", "0.5"], tmp_path, capsys)
    assert status == 0
    assert rep["n_samples"] == 400 and rep["n_validation_samples"] == 400


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--data", "{a}", "{missing}"], "no such data file or folder: {missing}"),
        (["--data", "{a}@9:10"], "holds no sample"),
        (["--data", "{a}@3:1"], "is empty"),
        (["--data", "{a}", "--torque-scale", "1,2"], "got 2 values"),
        (["--data", "{a}", "--torque-scale", "x"], "--torque-scale expects numbers"),
        (["--data", "{a}", "{three}"], "three.npz: the data have 3 joints"),
        (["--data", "{a}", "--velocity-deadband", "-1"], "--velocity-deadband must be positive"),
        (["--data", "{a}", "{b}", "--split", "0.5"], "--split cuts one file"),
        (["--simulate", "--window", "1:2"], "--window applies to --data files"),
    ],
)
def test_cli_bad_input(two_logs, tmp_path, capsys, args, message):
    pa, pb, a, _ = two_logs
    three = tmp_path / "three.npz"
    np.savez(three, t=a[0], q=a[1][:, :3], dq=a[2][:, :3], tau=a[4][:, :3])
    names = {"a": str(pa), "b": str(pb), "missing": str(tmp_path / "m.npz"), "three": str(three)}
    status, rep, cap = _cli([x.format(**names) for x in args], tmp_path, capsys)
    assert status == 2 and rep is None
    err = cap.err.strip().splitlines()
    assert len(err) == 1 and message.format(**names) in err[0], err


def test_cli_convert_round_trips(robot, two_logs, tmp_path, capsys):
    pa = two_logs[0]
    outs = [tmp_path / "c.csv", tmp_path / "c.npz", tmp_path / "c.mcap"]
    for out in outs:
        assert main(["convert", f"{pa}@#10:#510", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    z = np.load(pa)
    from manip_id.datasets import load_dataset

    for out in outs:
        ds = load_dataset(out)
        assert ds.n_samples == 500
        np.testing.assert_allclose(ds.t, z["t"][10:510], rtol=0, atol=1e-9)
        np.testing.assert_array_equal(ds.q, z["q"][10:510])
        np.testing.assert_array_equal(ds.tau, z["tau"][10:510])
        assert ds.joint_names == tuple(robot.dof_names)
    assert main(["convert", str(pa), str(pa)]) == 2  # never over an input
    assert main(["convert", str(pa), str(tmp_path / "x.h5")]) == 2


def test_save_dataset_mcap_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    n = 300
    t = 1.7e9 + np.arange(n) * 1e-3  # epoch stamps, as robots log them
    ds = Dataset(
        t=t,
        q=rng.normal(size=(n, 2)),
        dq=rng.normal(size=(n, 2)),
        tau=rng.normal(size=(n, 2)),
        joint_names=("a", "b"),
    )
    for name in ("s.mcap", "folder_bag"):
        path = save_dataset(ds, tmp_path / name, format="mcap")
        from manip_id.datasets import load_dataset

        back = load_dataset(path)
        np.testing.assert_allclose(back.t, t, rtol=0, atol=1e-6)  # ns stamps of epoch time
        np.testing.assert_array_equal(back.q, ds.q)
        np.testing.assert_array_equal(back.tau, ds.tau)
        assert back.joint_names == ("a", "b")


def test_parts_and_workers_add_up_to_the_whole_file(robot, base, tmp_path):
    t, q, dq, ddq, tau = log(robot, n=3000, rate=500.0, seed=8)
    path = save_npz(tmp_path / "w.npz", robot, t, q, dq, ddq, tau, with_ddq=False)
    opts = PreprocessOptions(cutoff=8.0, velocity_deadband=0.02)
    whole = accumulate_file(robot, path, opts, base.independent)
    parts = [accumulate_file(robot, path, opts, base.independent, part=(k, 3)) for k in range(3)]
    assert sum(p.n_samples for p in parts) == whole.n_samples
    np.testing.assert_array_equal(sum(p.excluded for p in parts), whole.excluded)
    A = sum(p.accumulator.A for p in parts)
    np.testing.assert_allclose(A, whole.accumulator.A, rtol=1e-10, atol=1e-8 * np.abs(A).max())
    serial = identify(robot, [path], base=base, files=FileOptions(preprocess=opts, audit=False))
    forked = identify(
        robot,
        [path],
        base=base,
        run=RunOptions(workers=2),
        files=FileOptions(preprocess=opts, audit=False),
    )
    assert forked.n_samples == serial.n_samples
    scale = np.abs(serial.estimate).max()
    np.testing.assert_allclose(forked.estimate, serial.estimate, rtol=0, atol=1e-9 * scale)


def test_cli_drop_bad_rows(robot, tmp_path, capsys):
    t, q, dq, ddq, tau = log(robot, n=900, seed=9)
    tau = tau.copy()
    tau[77, 4] = np.nan
    path = save_dataset(
        Dataset(
            t=t, q=q, dq=dq, tau=np.nan_to_num(tau, nan=0.0), ddq=ddq, joint_names=robot.dof_names
        ),
        tmp_path / "bad.csv",
    )
    text = path.read_text().splitlines()
    cells = text[78].split(",")
    cells[1 + 2 * robot.nv + 4] = "nan"  # tau of wrist_2_joint at row 77
    text[78] = ",".join(cells)
    path.write_text("\n".join(text) + "\n")
    status, rep, cap = _cli(["--data", str(path)], tmp_path, capsys)
    assert status == 2 and rep is None
    assert "bad.csv: tau holds nan at sample 77, wrist_2_joint" in cap.err
    assert "--drop-bad-rows" in cap.err
    status, rep, cap = _cli(["--data", str(path), "--drop-bad-rows"], tmp_path, capsys)
    assert status == 0
    assert rep["n_samples"] == 899
    assert (
        rep["data_quality"][0]["n_dropped"] == 1 and rep["data_quality"][0]["first_dropped"] == 77
    )


def test_every_format_gives_the_same_sums(robot, base, tmp_path):
    """NPZ (read twice), compressed NPZ and CSV (read once, then from the scan's copy)."""
    t, q, dq, ddq, tau = log(robot, n=2500, rate=500.0, seed=10)
    plain = save_npz(tmp_path / "p.npz", robot, t, q, dq, ddq, tau, with_ddq=False)
    packed = tmp_path / "z.npz"
    np.savez_compressed(packed, t=t, q=q, dq=dq, tau=tau, joint_names=np.array(robot.dof_names))
    ds = Dataset(t=t, q=q, dq=dq, tau=tau, joint_names=robot.dof_names)
    text = save_dataset(ds, tmp_path / "c.csv")
    opts = PreprocessOptions(cutoff=8.0)
    ref = accumulate_file(robot, plain, opts, base.independent).accumulator
    for path in (packed, text):
        scan = scan_file(robot, path, opts)
        assert scan.spill is not None
        acc = accumulate_file(robot, path, opts, base.independent, scan=scan).accumulator
        np.testing.assert_allclose(acc.A, ref.A, rtol=1e-12, atol=1e-12 * np.abs(ref.A).max())
        np.testing.assert_allclose(acc.b, ref.b, rtol=1e-12, atol=1e-12 * np.abs(ref.b).max())
        from pathlib import Path

        assert not Path(scan.spill).exists()  # removed once used
