"""Per-block sums of the accumulator and the covariance that holds for correlated residuals.

References independent of the code under test: sums over sample ranges computed
directly with numpy, the Monte Carlo spread of estimates over noise draws, and
Andrews' (1991) closed-form bandwidth for an AR(1).
"""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest
from conftest import get_robot

from manip_id import regressor
from manip_id.errors import InputError
from manip_id.estimators.accumulator import InformationAccumulator
from manip_id.estimators.batch import solve_accumulator
from manip_id.estimators.blocks import ScoreBlocks
from manip_id.estimators.uncertainty import (
    UncertaintyOptions,
    andrews_bandwidth,
    bartlett_weights,
    estimate_uncertainty,
    long_run_covariance,
    solution_uncertainty,
)
from manip_id.identifiability import analyze
from manip_id.simulation import simulate
from manip_id.trajectories import random_trajectory


def _random_problem(n=1000, nv=3, p=5, seed=0):
    rng = np.random.default_rng(seed)
    Y = rng.standard_normal((n, nv, p))
    tau = Y @ rng.standard_normal(p) + 0.1 * rng.standard_normal((n, nv))
    return Y, tau


def _ranges(counts):
    edges = np.concatenate([[0], np.cumsum(counts)])
    return list(zip(edges[:-1], edges[1:], strict=True))


# ----------------------------------------------------------------- block sums
def _acc(block_length: int, max_blocks: int, stream: int = 0, offset: int = 0):
    blocks = ScoreBlocks(5, 3, block_length, max_blocks, stream=stream, offset=offset)
    return InformationAccumulator(5, 3, blocks=blocks)


def test_blocks_off_and_on_give_bit_identical_totals():
    Y, tau = _random_problem()
    off, on = InformationAccumulator(5, 3), _acc(16, 8)
    for a in range(0, 1000, 37):
        off.add(Y[a : a + 37], tau[a : a + 37])
        on.add(Y[a : a + 37], tau[a : a + 37])
    assert off.blocks is None
    np.testing.assert_array_equal(on.A_joint, off.A_joint)
    np.testing.assert_array_equal(on.b_joint, off.b_joint)
    np.testing.assert_array_equal(on.zz_joint, off.zz_joint)
    assert on.n == off.n == 1000
    np.testing.assert_array_equal(solve_accumulator(on).estimate, solve_accumulator(off).estimate)


def test_block_sums_equal_direct_sums_over_their_samples():
    Y, tau = _random_problem()
    acc = _acc(16, 8)
    for a in range(0, 1000, 37):
        acc.add(Y[a : a + 37], tau[a : a + 37])
    blk = acc.blocks
    # 1000 samples, 16 per block, cap 8: the length doubles to 128 (8 * 128 >= 1000)
    assert blk.length == 128
    np.testing.assert_array_equal(blk.counts, [128] * 7 + [104])
    for k, (a, c) in enumerate(_ranges(blk.counts)):
        Yk, tk = Y[a:c], tau[a:c]
        np.testing.assert_allclose(
            blk.A_joint[k], np.einsum("nja,njb->jab", Yk, Yk), rtol=1e-12, atol=1e-10
        )
        np.testing.assert_allclose(blk.b_joint[k], np.einsum("nja,nj->ja", Yk, tk), atol=1e-10)
        np.testing.assert_allclose(blk.zz_joint[k], (tk**2).sum(axis=0), rtol=1e-12)
    np.testing.assert_allclose(blk.A_joint.sum(axis=0), acc.A_joint, rtol=1e-12, atol=1e-9)


def test_blocks_do_not_depend_on_the_chunking():
    Y, tau = _random_problem(n=700)
    accs = []
    for chunk in (1, 50, 700):
        acc = _acc(20, 16)
        for a in range(0, 700, chunk):
            acc.add(Y[a : a + chunk], tau[a : a + chunk])
        accs.append(acc.blocks)
    for other in accs[1:]:
        np.testing.assert_array_equal(other.counts, accs[0].counts)
        np.testing.assert_allclose(other.A_joint, accs[0].A_joint, rtol=1e-12, atol=1e-10)
        np.testing.assert_allclose(other.b_joint, accs[0].b_joint, atol=1e-10)


def test_parts_of_a_record_give_the_serial_blocks_whatever_the_cut_and_merge_order():
    Y, tau = _random_problem(n=1000)
    serial = _acc(16, 8).add(Y, tau).blocks
    cuts = [(0, 230), (230, 517), (517, 1000)]  # not on block boundaries
    parts = [_acc(16, 8, offset=a).add(Y[a:c], tau[a:c]) for a, c in cuts]
    assert parts[0].blocks.length == 32  # each part alone needs a lower level
    for merged in (
        (parts[0] + parts[1]) + parts[2],
        parts[0] + (parts[1] + parts[2]),
        (parts[2] + parts[0]) + parts[1],
    ):
        assert merged.blocks.length == serial.length == 128
        assert merged.blocks.keys == serial.keys
        np.testing.assert_array_equal(merged.blocks.counts, serial.counts)
        np.testing.assert_allclose(merged.blocks.A_joint, serial.A_joint, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(merged.blocks.b_joint, serial.b_joint, atol=1e-9)
    assert parts[0].blocks.n_blocks == 8  # __add__ leaves its operands alone


def test_records_are_streams_whose_ends_are_block_boundaries():
    Y, tau = _random_problem(n=1000)
    files = [(0, 300), (300, 650), (650, 1000)]
    accs = [_acc(16, 8, stream=f).add(Y[a:c], tau[a:c]) for f, (a, c) in enumerate(files)]
    assert accs[0].blocks.length == 64  # 300 samples alone: 5 blocks of 64
    one, other = (accs[0] + accs[1]) + accs[2], accs[2] + (accs[1] + accs[0])
    # together 17 blocks of 64 > 8, 9 of 128 > 8: 6 of 256, each file ending short
    np.testing.assert_array_equal(one.blocks.counts, [256, 44, 256, 94, 256, 94])
    assert one.blocks.keys == other.blocks.keys == [(0, 0), (0, 1), (1, 0), (1, 1), (2, 0), (2, 1)]
    np.testing.assert_allclose(one.blocks.b_joint, other.blocks.b_joint, atol=1e-10)
    for k, (a, c) in enumerate(_ranges(one.blocks.counts)):
        np.testing.assert_allclose(
            one.blocks.b_joint[k], np.einsum("nja,nj->ja", Y[a:c], tau[a:c]), atol=1e-10
        )
    # more records than the cap: one block each, none merged across records
    many = sum(
        (_acc(16, 4, stream=f).add(Y[20 * f : 20 * f + 20], tau[:20]) for f in range(10)),
        start=_acc(16, 4),
    )
    np.testing.assert_array_equal(many.blocks.counts, [20] * 10)
    with pytest.raises(InputError, match="block_length"):
        _acc(16, 8).merge(_acc(32, 8).add(Y[:10], tau[:10]))


def test_merge_with_data_without_blocks_drops_them():
    Y, tau = _random_problem(n=200)
    on = InformationAccumulator(5, 3, blocks=True).add(Y[:100], tau[:100])
    off = InformationAccumulator(5, 3).add(Y[100:], tau[100:])
    assert (on + off).blocks is None
    assert (on + InformationAccumulator(5, 3)).blocks is not None  # empty: nothing lost
    assert (InformationAccumulator(5, 3) + on).blocks.n_blocks == on.blocks.n_blocks
    with pytest.raises(InputError, match="empty ScoreBlocks"):
        InformationAccumulator(5, 3, blocks=on.blocks)


def test_rows_on_supports_and_deadband_equal_full_rows():
    Y, tau = _random_problem(n=300)
    Y[:, 0, 3:] = 0.0  # joint 0 sees columns 0..2 only
    supports = [np.arange(3), np.arange(5), np.arange(5)]
    keep = np.random.default_rng(1).random((300, 3)) > 0.3
    full = _acc(40, 4).add(np.where(keep[:, :, None], Y, 0.0), np.where(keep, tau, 0.0))
    blocks = ScoreBlocks(5, 3, block_length=40, max_blocks=4)
    for a in range(0, 300, 64):
        rows = [Y[a : a + 64, j, supports[j]] for j in range(3)]
        blocks.add_rows(rows, tau[a : a + 64], supports, keep[a : a + 64])
    np.testing.assert_array_equal(blocks.counts, full.blocks.counts)
    np.testing.assert_allclose(blocks.A_joint, full.blocks.A_joint, rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(blocks.b_joint, full.blocks.b_joint, atol=1e-10)
    np.testing.assert_allclose(blocks.zz_joint, full.blocks.zz_joint, rtol=1e-12)
    totals = InformationAccumulator(5, 3).add(np.where(keep[:, :, None], Y, 0.0), tau * keep)
    totals.attach_blocks(blocks)
    assert totals.blocks is blocks
    with pytest.raises(InputError, match="do not match"):
        InformationAccumulator(5, 3).add(Y[:10], tau[:10]).attach_blocks(blocks)


def test_add_sums_is_one_run_of_samples_in_the_block_of_its_middle():
    Y, tau = _random_problem(n=90)
    acc = _acc(40, 8)
    for a, c in ((0, 30), (30, 35), (35, 90)):  # middles 15, 32, 62: blocks 0, 0, 1
        part = InformationAccumulator(5, 3).add(Y[a:c], tau[a:c])
        acc.add_sums(part.A_joint, part.b_joint, part.zz_joint, part.n)
    np.testing.assert_array_equal(acc.blocks.counts, [35, 55])


def test_scores_are_block_regressor_times_residuals_and_pickle():
    Y, tau = _random_problem(n=400)
    acc = _acc(25, 16).add(Y, tau)
    theta = solve_accumulator(acc).estimate
    w = np.array([1.0, 2.0, 0.5])
    s = acc.blocks.scores(theta, w)
    for k, (a, c) in enumerate(_ranges(acc.blocks.counts)):
        e = tau[a:c] - Y[a:c] @ theta
        np.testing.assert_allclose(s[k], np.einsum("nja,nj,j->a", Y[a:c], e, w), atol=1e-9)
    np.testing.assert_allclose(acc.blocks.scores(theta).sum(axis=0), 0.0, atol=1e-8)
    back = pickle.loads(pickle.dumps(acc))
    np.testing.assert_array_equal(back.blocks.A_joint, acc.blocks.A_joint)
    assert back.blocks.keys == acc.blocks.keys


# ----------------------------------------------------------------- estimators
def test_bartlett_and_long_run_covariance_by_hand():
    np.testing.assert_allclose(bartlett_weights(2.5, 4), [1.0, 0.6, 0.2, 0.0])
    s = np.random.default_rng(2).standard_normal((9, 3))
    np.testing.assert_allclose(long_run_covariance(s, 0.7), s.T @ s)  # S <= 1: batch means
    by_hand = s.T @ s
    for h, w in ((1, 1 - 1 / 2.5), (2, 1 - 2 / 2.5)):
        g = sum(np.outer(s[k + h], s[k]) for k in range(9 - h))
        by_hand = by_hand + w * (g + g.T)
    np.testing.assert_allclose(long_run_covariance(s, 2.5), by_hand)
    assert np.linalg.eigvalsh(long_run_covariance(s, 2.5)).min() > -1e-12


def test_andrews_bandwidth_matches_the_closed_form_for_ar1():
    rho, B = 0.5, 20000
    rng = np.random.default_rng(3)
    x = np.zeros((B, 4))
    z = rng.standard_normal((B, 4))
    for k in range(1, B):
        x[k] = rho * x[k - 1] + z[k]
    x *= [1.0, 1e3, 1e-3, 5.0]  # the units of the parameters must not matter
    alpha = 4 * rho**2 / ((1 - rho) ** 6 * (1 + rho) ** 2) * (1 - rho) ** 4
    assert andrews_bandwidth(x) == pytest.approx(1.1447 * (alpha * B) ** (1 / 3), rel=0.03)
    white = rng.standard_normal((B, 4))
    # rho_a ~ N(0, 1/B) by chance: alpha ~ 4 / B, so S ~ 1.1447 4^(1/3) = 1.8 for any B
    assert andrews_bandwidth(white) < 2.5
    assert andrews_bandwidth(np.zeros((50, 2))) == 0.0


def test_auto_falls_back_to_white_with_a_reason_and_hac_needs_blocks():
    Y, tau = _random_problem(n=200)
    acc = _acc(50, 16).add(Y, tau)
    sol = solve_accumulator(acc)
    u = solution_uncertainty(acc, sol, "auto")
    assert u.method == "white" and "4 blocks" in u.reason
    np.testing.assert_array_equal(u.covariance, sol.covariance)
    assert u.inflation == 1.0
    assert solution_uncertainty(acc, sol, "hac").method == "hac"  # asked for: 4 blocks do
    plain = InformationAccumulator(5, 3).add(Y, tau)
    assert "not recorded" in solution_uncertainty(plain, sol).reason
    with pytest.raises(InputError, match="hac"):
        solution_uncertainty(plain, sol, "hac")
    with pytest.raises(InputError, match="uncertainty must be one of"):
        UncertaintyOptions(method="sandwich")
    with pytest.raises(InputError, match="unknown uncertainty option"):
        UncertaintyOptions.from_value({"kernel": "parzen"})
    with pytest.raises(InputError, match="bandwidth"):
        UncertaintyOptions(bandwidth=-1.0)
    d = solution_uncertainty(acc, sol, {"method": "hac", "bandwidth": 1.5}).to_dict()
    assert d["method"] == "hac" and d["bandwidth"] == 1.5 and d["n_blocks"] == 4


def test_white_residuals_are_not_inflated():
    """On independent, equal-variance noise the honest std agrees with the white one."""
    rng = np.random.default_rng(4)
    n, nv, p = 20000, 2, 6
    Y = rng.standard_normal((n, nv, p))
    tau = Y @ np.arange(1.0, p + 1) + rng.standard_normal((n, nv))
    acc = UncertaintyOptions().accumulator(p, nv).add(Y, tau)
    u = solution_uncertainty(acc, solve_accumulator(acc))
    assert u.method == "hac" and 64 <= u.n_blocks <= 128
    assert 0.85 <= u.inflation <= 1.15
    noise_free = UncertaintyOptions().accumulator(p, nv).add(Y, Y @ np.ones(p))
    sol = solve_accumulator(noise_free)
    np.testing.assert_allclose(solution_uncertainty(noise_free, sol).std, 0.0, atol=1e-9)


def test_estimate_uncertainty_checks_shapes():
    Y, tau = _random_problem(n=200)
    acc = _acc(10, 128).add(Y, tau)
    sol = solve_accumulator(acc)
    with pytest.raises(InputError, match="information_inverse"):
        estimate_uncertainty(acc, sol.estimate, sol.covariance, np.eye(4), options="hac")


# ----------------------------------------------------------------- Monte Carlo
N_SAMPLES = 16384
N_RUNS = 40
CORRELATION_TIME = 20.0  # [samples]: AR(1) phi = exp(-1/20)


@pytest.fixture(scope="module")
def ur5_excitation():
    """The base regressor and noise-free torques of one ur5 excitation, (N, 6, r) and (N, 6)."""
    robot = get_robot("ur5")
    ind = analyze(robot).base.independent
    traj = random_trajectory(robot, harmonics=5, seed=3)
    sim = simulate(robot, traj, duration=(N_SAMPLES - 1) / 100.0, rate=100.0)
    d = sim.dataset
    return regressor(robot, d.q, d.dq, d.ddq)[:, :, ind], d.tau


def _ar1_noise(rng, n: int, nv: int, phi: float) -> np.ndarray:
    """Stationary AR(1) noise of unit variance per column, shape (n, nv)."""
    from scipy.signal import lfilter  # optional heavy import (scipy.signal)

    z = rng.standard_normal((n, nv))
    z[1:] *= np.sqrt(1.0 - phi**2)
    return lfilter([1.0], [1.0, -phi], z, axis=0)


def test_block_hac_agrees_with_sample_level_batch_means_of_the_residuals(ur5_excitation):
    """One draw of correlated noise: the std from the streamed block scores against
    overlapping batch means of the per-sample scores ``Y_t^T e_t`` (residuals in memory,
    windows of H samples: ``Omega = n / (n - H + 1) sum_t w_t w_t^T / H``)."""
    Y, tau0 = ur5_excitation
    n, nv, r = Y.shape
    scale = 0.02 * np.sqrt((tau0**2).mean(axis=0))  # [N m]
    tau = tau0 + scale * _ar1_noise(np.random.default_rng(7), n, nv, np.exp(-1 / 20))
    acc = UncertaintyOptions().accumulator(r, nv).add(Y, tau)
    sol = solve_accumulator(acc)
    u = solution_uncertainty(acc, sol)
    scores = np.einsum("nja,nj->na", Y, tau - Y @ sol.estimate)  # (n, r)
    csum = np.vstack([np.zeros(r), np.cumsum(scores, axis=0)])
    Ainv = sol.covariance / sol.sigma2
    for H in (400, 800):
        w = csum[H:] - csum[:-H]
        omega = w.T @ w / H * n / (n - H + 1)
        std_obm = np.sqrt(np.diag(Ainv @ omega @ Ainv))
        assert 0.8 <= np.median(u.std / std_obm) <= 1.25, (H, np.median(u.std / std_obm))
    assert u.inflation > 2.5  # and both are far from the white std


@pytest.mark.slow
@pytest.mark.parametrize("method", ["ols", "wls"])
def test_monte_carlo_honest_std_matches_the_spread_and_white_does_not(ur5_excitation, method):
    """40 noise draws on one ur5 excitation, AR(1) torque noise of correlation time 20
    samples: the spread of the estimates over the draws against the mean reported std."""
    Y, tau0 = ur5_excitation
    n, nv, r = Y.shape
    scale = 0.02 * np.sqrt((tau0**2).mean(axis=0)) * [1.0, 1.0, 3.0, 1.0, 1.0, 0.3]  # [N m]
    phi = np.exp(-1.0 / CORRELATION_TIME)
    estimates, honest, white = [], [], []
    for run in range(N_RUNS):
        tau = tau0 + scale * _ar1_noise(np.random.default_rng(100 + run), n, nv, phi)
        acc = UncertaintyOptions().accumulator(r, nv)
        for a in range(0, n, 1000):
            acc.add(Y[a : a + 1000], tau[a : a + 1000], check=False)
        sol = solve_accumulator(acc, method=method)
        u = solution_uncertainty(acc, sol)
        assert u.method == "hac"
        estimates.append(sol.estimate)
        honest.append(u.std)
        white.append(u.std_white)
    spread = np.std(estimates, axis=0, ddof=1)
    ratio_honest = spread / np.mean(honest, axis=0)
    ratio_white = spread / np.mean(white, axis=0)
    assert 0.75 <= np.median(ratio_honest) <= 1.33, np.median(ratio_honest)
    lo, hi = np.quantile(ratio_honest, [0.1, 0.9])
    assert 0.6 <= lo and hi <= 1.6, (lo, hi)
    assert not 0.5 <= np.median(ratio_white) <= 2.0, np.median(ratio_white)


# ----------------------------------------------------------------- identify and the CLI
@pytest.fixture(scope="module")
def ur5_correlated():
    """4000 samples of one ur5 excitation with AR(1) torque noise (correlation 20 samples)."""
    robot = get_robot("ur5")
    traj = random_trajectory(robot, harmonics=5, seed=3)
    d = simulate(robot, traj, duration=39.99, rate=100.0).dataset
    scale = 0.02 * np.sqrt((d.tau**2).mean(axis=0))  # [N m]
    noise = _ar1_noise(np.random.default_rng(11), d.tau.shape[0], robot.nv, np.exp(-1 / 20))
    return robot, (d.q, d.dq, d.ddq, d.tau + scale * noise)


def test_identify_reports_the_honest_std_and_keeps_the_white_one(ur5_correlated, tmp_path):
    from manip_id.identification import RunOptions, identify, load_result

    robot, data = ur5_correlated
    honest = identify(robot, tuple(data))  # "auto"
    white = identify(robot, tuple(data), uncertainty="white")
    np.testing.assert_array_equal(honest.estimate, white.estimate)  # the same fit
    np.testing.assert_array_equal(honest.std_white, white.std)
    assert white.uncertainty["method"] == "white" and white.uncertainty["n_blocks"] == 0
    u = honest.uncertainty
    assert u["method"] == "hac" and u["requested"] == "auto" and 64 <= u["n_blocks"] <= 128
    assert u["inflation"] == pytest.approx(np.median(honest.std / honest.std_white), rel=1e-5)
    assert u["inflation"] > 2.5
    np.testing.assert_allclose(honest.std, np.sqrt(np.diag(honest.covariance)))
    # forked parts give the serial blocks (parts of one record merge exactly)
    forked = identify(robot, tuple(data), run=RunOptions(workers=2))
    np.testing.assert_allclose(forked.std, honest.std, rtol=1e-8)
    # the flags use the honest std: a threshold between the white and the honest std %
    white_pct = 100 * honest.std_white / np.abs(honest.estimate)
    limit = float(np.median(np.sqrt(white_pct * honest.std_percent)))
    flagged = [
        "poorly identified" in p["flags"]
        for p in honest.to_dict(poorly_identified=limit)["base_parameters"]
    ]
    assert sum(flagged) > sum(white_pct > limit)
    # JSON: the section and std_white per parameter, read back
    path = tmp_path / "result.json"
    path.write_text(json.dumps(honest.to_dict()))
    back = load_result(path)
    assert back.uncertainty == json.loads(path.read_text())["uncertainty"]
    np.testing.assert_allclose(back.std_white, honest.std_white, rtol=1e-12)
    np.testing.assert_allclose(back.std, honest.std, rtol=1e-12)
    assert back.to_dict()["uncertainty"] == honest.to_dict()["uncertainty"]


def test_short_records_fall_back_to_white_and_hac_can_be_forced(ur5_correlated):
    from manip_id.identification import identify

    robot, data = ur5_correlated
    short = tuple(a[:300] for a in data)  # 300 samples: 10 blocks of 32
    auto = identify(robot, tuple(short))
    assert auto.uncertainty["method"] == "white" and "10 blocks" in auto.uncertainty["reason"]
    np.testing.assert_array_equal(auto.std, auto.std_white)
    forced = identify(robot, tuple(short), uncertainty={"method": "hac", "bandwidth": 1.0})
    assert forced.uncertainty["method"] == "hac" and forced.uncertainty["bandwidth"] == 1.0
    with pytest.raises(InputError, match="uncertainty must be one of"):
        identify(robot, tuple(short), uncertainty="newey")


def test_online_methods_get_the_honest_std_at_their_estimate(ur5_correlated):
    from manip_id.identification import identify

    robot, data = ur5_correlated
    res = identify(robot, tuple(data), method="rls")
    assert res.uncertainty["method"] == "hac" and res.uncertainty["inflation"] > 2.5


def test_cli_uncertainty_flag(tmp_path, capsys):
    from manip_id.cli import main

    out = tmp_path / "out.json"
    args = ["identify", "ur5", "--simulate", "--duration", "20", "--rate", "100", "--seed", "3"]
    assert main([*args, "--json", str(out)]) == 0
    auto = json.loads(out.read_text())
    assert auto["uncertainty"]["method"] == "hac"
    assert "standard deviations: autocorrelation-consistent" in capsys.readouterr().out
    assert main([*args, "--uncertainty", "white", "--json", str(out), "--force"]) == 0
    white = json.loads(out.read_text())
    assert white["uncertainty"]["method"] == "white"
    for a, b in zip(auto["base_parameters"], white["base_parameters"], strict=True):
        assert a["value"] == b["value"] and a["std_white"] == b["std"]
    assert main([*args, "--uncertainty", "sandwich"]) == 2
    assert "--uncertainty" in capsys.readouterr().err


@pytest.mark.slow
def test_monte_carlo_through_identify(ur5_excitation):
    """The bite test on the public path: 30 draws through :func:`identify` (its own
    regressor, accumulation and solve), AR(1) noise of correlation time 30 samples."""
    from manip_id.identification import identify

    robot = get_robot("ur5")
    traj = random_trajectory(robot, harmonics=5, seed=3)
    d = simulate(robot, traj, duration=(8192 - 1) / 100.0, rate=100.0).dataset
    scale = 0.02 * np.sqrt((d.tau**2).mean(axis=0))  # [N m]
    estimates, honest, white = [], [], []
    for run in range(30):
        noise = _ar1_noise(np.random.default_rng(500 + run), d.tau.shape[0], 6, np.exp(-1 / 30))
        res = identify(robot, (d.q, d.dq, d.ddq, d.tau + scale * noise))
        assert res.uncertainty["method"] == "hac"
        estimates.append(res.estimate)
        honest.append(res.std)
        white.append(res.std_white)
    spread = np.std(estimates, axis=0, ddof=1)
    ratio_honest = float(np.median(spread / np.mean(honest, axis=0)))
    ratio_white = float(np.median(spread / np.mean(white, axis=0)))
    assert 0.75 <= ratio_honest <= 1.33, ratio_honest
    assert not 0.5 <= ratio_white <= 2.0, ratio_white
