"""Stream adjustments of a FileSpec: time unit, torque delay, plausible rates."""

from __future__ import annotations

import numpy as np
import pytest

from manip_id.datasets import Dataset, FileSpec, Window, iter_rows, open_source, save_dataset
from manip_id.datasets.adjust import check_rate, delay_vector, likely_time_unit
from manip_id.datasets.stream import collect
from manip_id.errors import DataError, InputError

RATE = 200.0


@pytest.fixture()
def npz(tmp_path):
    t = 0.3 + np.arange(1000) / RATE
    q = np.column_stack([np.sin(t), np.cos(t)])
    tau = np.column_stack([np.sin(3 * t), np.cos(2 * t)])
    save_dataset(Dataset(t, q, -q, tau), tmp_path / "a.npz")
    return tmp_path / "a.npz", t, tau


def _read(spec, chunk=97, window=None):
    src = open_source(spec)
    return collect(iter_rows(src, window, chunk=chunk), src.layout, None)


@pytest.mark.parametrize("chunk", [7, 97, 5000])
@pytest.mark.parametrize("delay", [0.025, -0.0125, (0.025, -0.01), (0.0, 0.0173)])
def test_delay_reads_the_torque_later(npz, chunk, delay):
    path, t, tau = npz
    ds = _read(FileSpec(path, delay=delay), chunk)
    d = np.broadcast_to(np.asarray(delay, float), (2,))
    # rows kept: those whose shifted stamp stays inside the file
    inside = (t + d.min() >= t[0] - 1e-12) & (t + d.max() <= t[-1] + 1e-12)
    np.testing.assert_array_equal(ds.t, t[inside])
    # whole steps move whole rows; other delays interpolate linearly (independent: numpy)
    want = np.column_stack([np.interp(ds.t + d[j], t, tau[:, j]) for j in range(2)])
    np.testing.assert_allclose(ds.tau, want, rtol=0, atol=1e-12)
    if delay == 0.025:
        np.testing.assert_allclose(ds.tau, tau[5:], atol=1e-12)  # 5 rows at 200 Hz


def test_delay_keeps_row_indices_and_passes_bad_rows(tmp_path):
    t = np.arange(400) / RATE
    q = np.column_stack([np.sin(t)])
    tau = np.cos(t)[:, None]
    tau_bad = tau.copy()
    tau_bad[100] = np.nan
    np.savez(tmp_path / "b.npz", t=t, q=q, dq=q, tau=tau_bad)
    spec = FileSpec(tmp_path / "b.npz", delay=0.01)  # two rows
    with pytest.raises(DataError, match="tau holds nan"):
        _read(spec)
    src = open_source(spec)
    rows = np.vstack(list(iter_rows(src, Window(10, 20, "index"), drop_bad_rows=True)))
    np.testing.assert_allclose(rows[:, 0], t[10:20])
    np.testing.assert_allclose(rows[:, 3], tau[12:22, 0], atol=1e-12)


def test_time_unit(npz, tmp_path):
    path, t, tau = npz
    t_ms = t * 1e3
    save_dataset(
        Dataset(t_ms, np.zeros((t.size, 1)), np.zeros((t.size, 1)), tau[:, :1]), tmp_path / "ms.npz"
    )
    ds = _read(FileSpec(tmp_path / "ms.npz", time_unit="ms"), window=Window(1.0, 2.0))
    ts = t_ms * 1e-3  # the stamps in seconds, as the reader converts them
    np.testing.assert_array_equal(ds.t, ts[(ts - ts[0] >= 1.0) & (ts - ts[0] < 2.0)])
    with pytest.raises(InputError, match="time unit must be one of s, ms, us, ns"):
        FileSpec(path, time_unit="min")
    with pytest.raises(InputError, match="finite"):
        FileSpec(path, delay=float("nan"))
    with pytest.raises(InputError, match="one value or one per joint"):
        _read(FileSpec(path, delay=(0.1, 0.2, 0.3)))
    assert FileSpec(path, delay=[0.01]).delay == 0.01
    assert FileSpec(path, time_unit="ns").with_window(Window(1, 2)).time_unit == "ns"


def test_rates():
    assert check_rate(1e-3, "f") == pytest.approx(1e3)
    with pytest.raises(DataError, match=r"stamps in ns\? pass --time-unit ns"):
        check_rate(1e6, "f")  # 1e6 "seconds" per step: nanoseconds at 1 kHz
    with pytest.raises(DataError, match=r"stamps in ms\? pass --time-unit ms"):
        check_rate(4.0, "f")
    with pytest.raises(DataError, match="sample indices"):
        check_rate(1e-7, "f")  # 10 MHz: no unit makes it plausible
    with pytest.raises(DataError, match=r"step 0.005 \[ns\].*stamps in s\? pass --time-unit s"):
        check_rate(0.005 * 1e-9, "f", "ns")  # said ns, but the stamps are seconds
    assert likely_time_unit(5e6) == "ns" and likely_time_unit(0.005) == "s"
    np.testing.assert_array_equal(delay_vector(0.5, 3), [0.5, 0.5, 0.5])
    assert delay_vector(None, 3) is None
