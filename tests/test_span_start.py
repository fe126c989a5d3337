"""A part of a file read from one filter margin before it: the whole pass's rows, bit for bit.

Each forked worker of a one-file accumulation starts reading and filtering at
:func:`~manip_id.signals.read_start` (the block holding its first row, less the blocked
filter's margin) instead of the file's first row. Its processed rows must be the whole
pass's (bit-equal) and the parts' sums must add up to the serial sums (1e-12), for NPZ and
CSV, with and without accelerations, filtering, trimming, decimation and windows; a start
later than the margin must show.
"""

from __future__ import annotations

import numpy as np
import pytest

import manip_id.identification.reading as reading
from manip_id import load_robot
from manip_id.datasets import Dataset, save_dataset
from manip_id.identification import PreprocessOptions, iter_processed, scan_file
from manip_id.identification.file_sums import accumulate_file
from manip_id.signals import (
    Lowpass,
    SignalOptions,
    StreamStats,
    overlap_margin,
    preprocess_blocks,
    read_start,
)
from manip_id.simulation import MeasurementNoise, simulate
from manip_id.trajectories import random_trajectory

BLOCK = 256  # rows per preprocessing block: several blocks in a file of 1500 rows


@pytest.fixture(scope="module")
def robot():
    return load_robot("ur5", friction=("viscous", "coulomb"))


@pytest.fixture(scope="module")
def data(robot):
    traj = random_trajectory(robot, harmonics=4, seed=7)
    noise = MeasurementNoise(tau=0.01, q=1e-5)
    return simulate(robot, traj, duration=6.0, rate=250.0, noise=noise, seed=7).dataset


def _file(tmp_path, robot, d, fmt: str, ddq: bool):
    """``fmt``: npz, csv, "z.npz" (compressed: spilled by the scan) or "nan.npz" (a row
    of NaN, dropped with ``drop_bad_rows``: the rows are read from the first and skipped)."""
    names = tuple(robot.dof_names)
    if fmt in ("z.npz", "nan.npz"):
        fields = {"t": d.t, "q": d.q.copy(), "dq": d.dq, "tau": d.tau}
        if ddq:
            fields["ddq"] = d.ddq
        fields["q"][400, 1] = np.nan
        path = tmp_path / f"log.{fmt}"
        save = np.savez_compressed if fmt == "z.npz" else np.savez
        if fmt == "z.npz":
            fields["q"][400, 1] = d.q[400, 1]
        save(path, joint_names=np.array(names), **fields)
        return path
    ds = Dataset(d.t, d.q, d.dq, d.tau, ddq=d.ddq if ddq else None, joint_names=names)
    return save_dataset(ds, tmp_path / f"log.{fmt}")


def _rows(robot, spec, options, scan, start=0):
    settings, blocks = iter_processed(robot, spec, options, scan, start=start)
    return settings, np.concatenate(list(blocks))


def _stream(x, first, chunk=300):
    for i in range(first, x.shape[0], chunk):
        yield x[i : i + chunk]


def _series(n=3000, nq=2, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.004
    return t, np.column_stack([t, np.cumsum(rng.normal(size=(n, 3 * nq)), axis=0) * 1e-2])


@pytest.mark.parametrize(
    "opts",
    [
        SignalOptions(cutoff=20.0),
        SignalOptions(cutoff=12.0, decimate=3, trim=0.05, filter_torque=True),
        SignalOptions(cutoff=30.0, velocity="differentiate", decimate=2),
    ],
)
def test_blocks_from_read_start_are_the_whole_streams(opts):
    t, x = _series()
    stats = StreamStats.of(t)
    _, blocks = preprocess_blocks(_stream(x, 0), 2, 2, stats, options=opts, block=BLOCK)
    whole = np.concatenate(list(blocks))
    for s in (1, 40, 170, 171, BLOCK - 1, BLOCK, 700, whole.shape[0] - 1, whole.shape[0] + 2):
        r0 = read_start(stats, opts, BLOCK, s)
        _, blocks = preprocess_blocks(
            _stream(x, r0), 2, 2, stats, options=opts, block=BLOCK, start=s
        )
        part = list(blocks)
        part = np.concatenate(part) if part else whole[:0]
        assert np.array_equal(part, whole[s:]), s


def test_a_start_inside_the_margin_changes_the_rows():
    t, x = _series()
    stats, opts = StreamStats.of(t), SignalOptions(cutoff=20.0)
    margin = overlap_margin(Lowpass(20.0, 1 / 0.004))
    _, blocks = preprocess_blocks(_stream(x, 0), 2, 2, stats, options=opts, block=BLOCK)
    whole = np.concatenate(list(blocks))
    s = 4 * BLOCK + 10
    r0 = read_start(stats, opts, BLOCK, s)
    assert 0 < r0 == 4 * BLOCK - margin
    for late, floor in ((r0 + margin // 2, 0.0), (4 * BLOCK - 4, 1e-9)):
        _, blocks = preprocess_blocks(
            _stream(x, late), 2, 2, stats, options=opts, block=BLOCK, start=s, first_row=late
        )
        part = np.concatenate(list(blocks))
        assert part.shape == whole[s:].shape
        assert np.abs(part - whole[s:]).max() > floor * np.abs(whole).max()


def test_a_resampled_stream_is_read_from_its_first_row():
    t, x = _series()
    t = t + np.random.default_rng(1).uniform(0, 1e-3, t.shape)  # non-uniform stamps
    x[:, 0] = t
    stats, opts = StreamStats.of(t), SignalOptions(cutoff=20.0)
    assert read_start(stats, opts, BLOCK, 1000) == 0
    _, blocks = preprocess_blocks(_stream(x, 0), 2, 2, stats, options=opts, block=BLOCK)
    whole = np.concatenate(list(blocks))
    _, blocks = preprocess_blocks(_stream(x, 0), 2, 2, stats, options=opts, block=BLOCK, start=900)
    assert np.array_equal(np.concatenate(list(blocks)), whole[900:])


CASES = [
    ("npz", True, {}, None),
    ("npz", False, {}, None),
    ("npz", True, {"cutoff": 10.0}, None),
    ("npz", False, {"cutoff": 12.0, "trim": 0.1, "decimate": 2}, "#100:1400"),
    ("npz", False, {"cutoff": 10.0, "filter_torque": True}, "0.5:5.5"),
    ("csv", False, {}, None),
    ("csv", True, {"cutoff": 12.0, "trim": 0.2}, "1.0:5.0"),
    ("csv", False, {"cutoff": 10.0, "decimate": 3}, "#50:"),
    ("z.npz", False, {"cutoff": 10.0}, "#20:1450"),
    ("nan.npz", False, {"drop_bad_rows": True}, None),
    ("nan.npz", True, {"drop_bad_rows": True, "cutoff": 15.0}, "#10:"),
]


@pytest.mark.parametrize(("fmt", "ddq", "opts", "window"), CASES)
def test_span_rows_and_sums_equal_the_serial_pass(tmp_path, robot, data, fmt, ddq, opts, window):
    path = _file(tmp_path, robot, data, fmt, ddq)
    spec = str(path) if window is None else f"{path}@{window}"
    options = PreprocessOptions(block=BLOCK, read_chunk=200, **opts)
    scan = scan_file(robot, spec, options)
    assert (scan.spill is not None) == (fmt in ("csv", "z.npz"))  # read back by a seek
    assert scan.counts.n_dropped == (fmt == "nan.npz")  # read from the first row, skipped
    try:
        _, whole = _rows(robot, scan.spec, options, scan)
        n = whole.shape[0]
        for s in (1, n // 3, n // 2 + 7, n - 5):
            _, part = _rows(robot, scan.spec, options, scan, start=s)
            assert np.array_equal(part, whole[s:]), s
        serial = accumulate_file(robot, spec, options, scan=scan, part=(0, 1))
        for k_parts in (2, 3):
            parts = [
                accumulate_file(robot, spec, options, scan=scan, part=(k, k_parts))
                for k in range(k_parts)
            ]
            total = parts[0]
            for p in parts[1:]:
                total = total.merged(p)
            a, b = total.accumulator, serial.accumulator
            assert a.n == b.n == whole.shape[0]
            for x, y in ((a.A, b.A), (a.b, b.b), (a.zz, b.zz)):
                np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-12 * np.abs(y).max())
    finally:
        scan.discard()


def test_a_worker_starting_too_late_breaks_the_rows(tmp_path, robot, data, monkeypatch):
    path = _file(tmp_path, robot, data, "npz", False)
    options = PreprocessOptions(block=128, cutoff=10.0)  # margin 505 rows
    scan = scan_file(robot, str(path), options)
    _, whole = _rows(robot, scan.spec, options, scan)
    serial = accumulate_file(robot, str(path), options, scan=scan, part=(0, 1))
    margin = overlap_margin(Lowpass(10.0, 250.0))
    less = margin - 4  # 4 rows before the block instead of the margin
    exact, starts = read_start, []

    def late(stats, opts, block, start):  # the margin cut short
        r0 = exact(stats, opts, block, start)
        starts.append(r0)
        return r0 + less if r0 else r0

    monkeypatch.setattr(reading, "read_start", late)
    s = 900  # its block starts at uniform row 896 (the trim: 83 rows), read from 391
    _, part = _rows(robot, scan.spec, options, scan, start=s)
    assert part.shape == whole[s:].shape and not np.array_equal(part, whole[s:])
    parts = [accumulate_file(robot, str(path), options, scan=scan, part=(k, 2)) for k in (0, 1)]
    scan.discard()
    total = parts[0].merged(parts[1])
    a, b = total.accumulator, serial.accumulator
    assert a.n == b.n
    assert not np.allclose(a.b, b.b, rtol=1e-9, atol=0)  # the filter's start transient
    assert starts.count(0) < len(starts)  # the late starts were taken
