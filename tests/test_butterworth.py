"""The closed-form Butterworth design and the zero-phase filter, against scipy.signal."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal as ss

from manip_id.signals import Lowpass, overlap_margin
from manip_id.signals import butterworth as bw


def _cases(seed: int, n: int):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        rate = float(rng.uniform(1.0, 5000.0))
        yield int(rng.integers(1, 9)), float(rng.uniform(0.002, 0.498)) * rate, rate, rng


@pytest.mark.filterwarnings("ignore::scipy.signal.BadCoefficients")  # scipy's own, order 20
@pytest.mark.parametrize("order", range(1, 21))
def test_design_equals_scipy_butter(order):
    rng = np.random.default_rng(order)
    for _ in range(20):
        rate = float(rng.uniform(1.0, 5000.0))
        cutoff = float(rng.uniform(0.001, 0.499)) * rate
        ours = bw.butterworth_sos(order, cutoff, rate)
        ref = ss.butter(order, cutoff, btype="low", fs=rate, output="sos")
        assert ours.shape == ref.shape
        np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-12 * np.abs(ref).max())
        _, poles, _ = ss.sos2zpk(ref)
        poles = poles[np.abs(poles) > 0]  # without the pole at 0 of an odd order's section
        np.testing.assert_allclose(
            np.sort(np.abs(bw.butterworth_poles(order, cutoff, rate)[0])),
            np.sort(np.abs(poles)),
            atol=1e-12,
        )


def test_initial_states_and_pad_length_equal_scipy():
    for order, cutoff, rate, _ in _cases(1, 40):
        sos = bw.butterworth_sos(order, cutoff, rate)
        np.testing.assert_allclose(bw.sosfilt_zi(sos), ss.sosfilt_zi(sos), rtol=1e-12, atol=0)
        n = bw.pad_length(sos)
        x = np.random.default_rng(order).standard_normal(n + 1)
        ss.sosfiltfilt(sos, x)  # the shortest series scipy accepts ...
        with pytest.raises(ValueError):
            ss.sosfiltfilt(sos, x[:n])  # ... and one sample fewer it refuses


@pytest.mark.parametrize("numba", [True, False])
def test_zero_phase_equals_sosfiltfilt(numba, monkeypatch):
    if not numba:  # the fallback without numba: scipy.signal itself
        monkeypatch.setattr(bw, "numba_available", lambda: False)
    elif not bw.numba_available():
        pytest.skip("numba not installed")
    for order, cutoff, rate, rng in _cases(2, 30):
        sos = bw.butterworth_sos(order, cutoff, rate)
        n = int(rng.integers(bw.pad_length(sos) + 1, 4000))
        shape = [(n,), (n, 3), (4, n, 2)][int(rng.integers(0, 3))]
        axis = 1 if len(shape) == 3 else 0
        x = rng.standard_normal(shape).cumsum(axis=axis)
        ref = ss.sosfiltfilt(sos, x, axis=axis)
        got = bw.zero_phase(sos, x, axis=axis)
        assert got.shape == x.shape
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("numba", [True, False])
def test_impulse_response_equals_sosfilt(numba, monkeypatch):
    if not numba:
        monkeypatch.setattr(bw, "numba_available", lambda: False)
    for order, cutoff, rate, _ in _cases(3, 20):
        sos = bw.butterworth_sos(order, cutoff, rate)
        impulse = np.zeros(500)
        impulse[0] = 1.0
        ref = ss.sosfilt(sos, impulse)
        got = bw.impulse_response(sos, 500)
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12 * np.abs(ref).max())


def test_lowpass_and_margin_use_scipys_filter():
    filt = Lowpass(3.0, 1000.0, 4)
    ref = ss.butter(4, 3.0, fs=1000.0, output="sos")
    x = np.random.default_rng(4).standard_normal((3000, 5))
    np.testing.assert_allclose(filt(x), ss.sosfiltfilt(ref, x, axis=0), rtol=0, atol=1e-13)
    _, poles, _ = ss.sos2zpk(ref)
    r = float(np.max(np.abs(poles)))
    expected = int(1.25 * np.ceil(np.log(1e-16) / np.log(r))) + 3 * (2 * ref.shape[0] + 1) + 8
    assert overlap_margin(filt) == expected
