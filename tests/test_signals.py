"""Signal processing against signals of known spectra and derivatives."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import get_robot

from manip_id import regressor
from manip_id.datasets import Dataset
from manip_id.errors import InputError
from manip_id.signals import (
    Lowpass,
    derivative,
    downsample,
    filter_regressor,
    is_uniform,
    lowpass,
    preprocess,
    resample,
    sampling_rate,
    trim_samples,
    uniform_grid,
)

RATE = 1000.0


def _sine(f: float, seconds: float = 20.0, phase: float = 0.3):
    t = np.arange(int(seconds * RATE)) / RATE
    return t, np.sin(2 * np.pi * f * t + phase)


def _amplitude_phase(t, x, f):
    """Least-squares amplitude and phase of the component sin(2 pi f t + phi)."""
    A = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])
    (s, c), *_ = np.linalg.lstsq(A, x, rcond=None)
    return np.hypot(s, c), np.arctan2(c, s)


@pytest.mark.parametrize("f", [0.1, 0.5, 1.0])
def test_sine_below_cutoff_passes_with_unit_gain_zero_phase(f):
    t, x = _sine(f)
    y = lowpass(x, cutoff=10.0, rate=RATE, order=4)
    mid = slice(2000, -2000)
    amp, phase = _amplitude_phase(t[mid], y[mid], f)
    assert amp == pytest.approx(1.0, abs=1e-6)
    assert phase == pytest.approx(0.3, abs=1e-6)
    assert np.max(np.abs(y[mid] - x[mid])) < 1e-5


@pytest.mark.parametrize(("f", "order"), [(20.0, 2), (20.0, 4), (40.0, 4), (10.0, 6), (5.0, 4)])
def test_attenuation_matches_butterworth(f, order):
    """Forward-backward gain 1 / (1 + (tan(pi f/fs) / tan(pi fc/fs))^(2n)), bilinear Butterworth."""
    fc = 5.0
    t, x = _sine(f, seconds=10.0)
    y = lowpass(x, cutoff=fc, rate=RATE, order=order)
    mid = slice(3000, -3000)
    amp, phase = _amplitude_phase(t[mid], y[mid], f)
    ratio = np.tan(np.pi * f / RATE) / np.tan(np.pi * fc / RATE)
    expected = 1.0 / (1.0 + ratio ** (2 * order))
    assert amp == pytest.approx(expected, rel=1e-4, abs=1e-12)
    assert Lowpass(fc, RATE, order).gain(f) == pytest.approx(expected, rel=1e-12)
    if amp > 1e-6:
        assert phase == pytest.approx(0.3, abs=1e-4)  # zero phase even in the stop band


def test_gain_at_cutoff_is_one_half():
    assert Lowpass(7.0, RATE, 3).gain(7.0) == pytest.approx(0.5, rel=1e-12)


def test_transient_bounds_edge_error():
    """Beyond the edge transient the filtered in-band signal is exact; inside it, not quite."""
    filt = Lowpass(5.0, RATE, 4)
    n = filt.transient_samples()
    t, x = _sine(0.37, seconds=10.0)
    x = x + 0.5 * t  # plus a ramp, which the odd padding of sosfiltfilt extends exactly
    y = filt(x)
    assert 0 < n < len(x) // 4
    assert np.max(np.abs(y[n:-n] - x[n:-n])) < 1e-4


@pytest.mark.parametrize("f", [0.2, 1.5])
def test_central_difference_derivatives_of_sines(f):
    t, x = _sine(f, seconds=5.0)
    w = 2 * np.pi * f
    dx = derivative(t, x)
    ddx = derivative(t, dx)
    h = 1 / RATE
    # central-difference truncation error: h^2/6 |x'''| for dx, about h^2/12 |x''''|... per pass
    assert np.max(np.abs(dx[1:-1] - w * np.cos(w * t[1:-1] + 0.3))) < w**3 * h**2 / 6 * 1.01 + 1e-12
    assert (
        np.max(np.abs(ddx[2:-2] + w**2 * np.sin(w * t[2:-2] + 0.3))) < w**4 * h**2 / 3 * 1.01 + 1e-9
    )
    assert np.max(np.abs(dx - w * np.cos(w * t + 0.3))) < 10 * w**3 * h**2 + 1e-12  # ends too


def test_derivative_on_non_uniform_stamps():
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.uniform(0.8e-3, 1.2e-3, 5000))
    x = np.column_stack([np.sin(3 * t), t**2])
    dx = derivative(t, x)
    assert np.max(np.abs(dx[:, 0] - 3 * np.cos(3 * t))) < 1e-4
    assert np.max(np.abs(dx[:, 1] - 2 * t)) < 1e-9  # exact on quadratics


def test_resample_is_exact_on_cubics_and_close_on_sines():
    rng = np.random.default_rng(1)
    t = np.concatenate([[0.0], np.cumsum(rng.uniform(0.7e-3, 1.6e-3, 3000))])
    x = np.column_stack([1 + t - 2 * t**2 + 0.5 * t**3, np.sin(2 * np.pi * 0.5 * t)])
    rate = sampling_rate(t)
    grid = uniform_grid(t[0], t[-1], rate)
    assert is_uniform(grid) and not is_uniform(t)
    assert grid[-1] <= t[-1] and grid[-1] > t[-1] - 1 / rate
    y = resample(t, x, grid)
    cubic = 1 + grid - 2 * grid**2 + 0.5 * grid**3
    assert np.max(np.abs(y[:, 0] - cubic)) < 1e-9
    assert np.max(np.abs(y[:, 1] - np.sin(np.pi * grid))) < 1e-9
    lin = resample(t, x, grid, kind="linear")
    assert np.max(np.abs(lin[:, 1] - np.sin(np.pi * grid))) < 1e-5


def test_parallel_filtering_commutes_with_the_model():
    robot = get_robot("ur5", friction="viscous,coulomb")
    rng = np.random.default_rng(2)
    n = 600
    t = np.arange(n) / 200.0
    q = 0.5 * np.sin(np.outer(t, np.linspace(0.5, 1.5, robot.nv)))
    dq = (
        0.5 * np.linspace(0.5, 1.5, robot.nv) * np.cos(np.outer(t, np.linspace(0.5, 1.5, robot.nv)))
    )
    ddq = rng.normal(size=(n, robot.nv))
    Y = regressor(robot, q, dq, ddq)
    theta = rng.normal(size=robot.n_parameters)
    filt = Lowpass(10.0, 200.0, 4)
    Yf = filter_regressor(Y, filt, block=7)
    np.testing.assert_allclose(Yf @ theta, filt(Y @ theta), atol=1e-9)
    np.testing.assert_allclose(Yf[:, :, 5], filt(Y[:, :, 5]), atol=1e-12)
    Y_in_place = Y.copy()
    filter_regressor(Y_in_place, filt, out=Y_in_place)
    np.testing.assert_allclose(Y_in_place, Yf, atol=1e-12)


def _sine_dataset(n=6000, rate=RATE, jitter=0.0, noise=0.0, seed=0):
    rng = np.random.default_rng(seed)
    dt = np.full(n - 1, 1 / rate) * (1 + jitter * rng.uniform(-1, 1, n - 1))
    t = np.concatenate([[0.0], np.cumsum(dt)])
    w = np.array([0.5, 1.1]) * 2 * np.pi
    q = np.sin(np.outer(t, w))
    dq = w * np.cos(np.outer(t, w))
    tau = 3 * q + noise * rng.normal(size=q.shape)
    return Dataset(
        t=t, q=q, dq=dq + noise * rng.normal(size=q.shape), tau=tau, joint_names=("a", "b")
    ), w


@pytest.mark.parametrize("velocity", ["measured", "differentiate"])
def test_preprocess_recovers_acceleration(velocity):
    ds, w = _sine_dataset(jitter=0.3, noise=0.01)
    out = preprocess(ds, cutoff=5.0, order=4, velocity=velocity)
    assert out.ddq is not None and is_uniform(out.t)
    assert out.meta["preprocess"].resampled
    ddq_true = -(w**2) * np.sin(np.outer(out.t, w))
    assert np.max(np.abs(out.ddq - ddq_true)) < 0.05 * np.max(np.abs(ddq_true))
    np.testing.assert_allclose(out.tau, 3 * np.sin(np.outer(out.t, w)), atol=0.01)
    trimmed = out.meta["preprocess"].trim
    assert trimmed == Lowpass(5.0, out.meta["preprocess"].rate, 4).transient_samples()
    assert out.t[0] == pytest.approx(ds.t[0] + trimmed / out.meta["preprocess"].rate)


def test_preprocess_decimates_and_trims():
    ds, _ = _sine_dataset()
    out = preprocess(ds, cutoff=5.0, decimate=10, trim=0.5)
    assert out.meta["preprocess"].trim == 500
    assert np.allclose(np.diff(out.t), 0.01)
    assert out.n_samples == len(range(500, ds.n_samples - 500, 10))
    assert not out.meta["preprocess"].resampled  # already uniform


def test_preprocess_rejects_aliasing_decimation():
    ds, _ = _sine_dataset()
    with pytest.raises(InputError, match="alias"):
        preprocess(ds, cutoff=50.0, decimate=20)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"cutoff": 600.0, "rate": 1000.0}, "cut-off"),
        ({"cutoff": -1.0}, "cut-off"),
        ({"order": 0}, "order"),
        ({"cutoff": 5.0, "velocity": "x"}, "velocity"),
    ],
)
def test_bad_filter_settings(kwargs, match):
    ds, _ = _sine_dataset(n=500)
    with pytest.raises(InputError, match=match):
        preprocess(ds, **kwargs)


def test_downsample_and_trim_samples():
    ds, _ = _sine_dataset(n=100)
    assert downsample(ds, 3).n_samples == 34
    assert trim_samples(ds, 10, 5).t[0] == ds.t[10]
    assert trim_samples(ds, 10, 5).n_samples == 85
    with pytest.raises(InputError):
        downsample(ds, 0)
