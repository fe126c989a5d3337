"""Blocked (overlapping-window) preprocessing equals the whole-series path to 1e-9."""

from __future__ import annotations

import numpy as np
import pytest

from manip_id.datasets import Dataset, Layout
from manip_id.signals import (
    Lowpass,
    SignalOptions,
    StreamStats,
    iter_overlapping,
    overlap_margin,
    preprocess,
    preprocess_blocks,
)


def _series(n, nv, jitter, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 500.0
    if jitter:
        t = t + rng.uniform(-3e-4, 3e-4, n)
    w = np.array([0.7, 1.3, 2.9])[:nv]
    q = np.sin(np.outer(t, w)) + 0.01 * rng.standard_normal((n, nv))
    dq = w * np.cos(np.outer(t, w)) + 0.01 * rng.standard_normal((n, nv))
    tau = 5 * rng.standard_normal((n, nv))
    return Dataset(t=t, q=q, dq=dq, tau=tau)


def _blocked(ds, chunk, block, **kw):
    lay = Layout(ds.q.shape[1], ds.nv)
    rows = lay.pack(ds.t, ds.q, ds.dq, ds.tau)
    chunks = [rows[i : i + chunk] for i in range(0, ds.n_samples, chunk)]
    stats = StreamStats.of(ds.t)
    options = SignalOptions(**kw)
    settings, it = preprocess_blocks(chunks, lay.nq, lay.nv, stats, options=options, block=block)
    return settings, np.vstack(list(it))


@pytest.mark.parametrize("jitter", [False, True])
@pytest.mark.parametrize(
    "kw",
    [{}, {"decimate": 3, "cutoff": 20.0}, {"velocity": "differentiate", "trim": 0.5}],
)
def test_blocked_preprocess_equals_whole_series(jitter, kw):
    ds = _series(20000, 3, jitter)
    ref = preprocess(ds, **kw)
    settings, out = _blocked(ds, chunk=1237, block=3001, **kw)
    assert settings == ref.meta["preprocess"]
    expect = np.column_stack([ref.t, ref.q, ref.dq, ref.tau, ref.ddq])
    assert out.shape == expect.shape
    scale = np.abs(expect).max(axis=0)
    np.testing.assert_allclose(out / scale, expect / scale, rtol=0, atol=1e-9)


def test_a_short_margin_is_visible():
    """The identity needs its margin: with a tenth of it the blocks differ (the test can fail)."""
    ds = _series(20000, 2, False)
    filt = Lowpass(3.0, 500.0)
    x = ds.tau
    whole = filt(x)
    for margin, close in ((overlap_margin(filt), True), (overlap_margin(filt) // 10, False)):
        parts = []
        for w in iter_overlapping([x[i : i + 999] for i in range(0, len(x), 999)], 2500, margin):
            parts.append(filt(w.rows)[w.centre])
        got = np.vstack(parts)
        err = np.abs(got - whole).max() / np.abs(whole).max()
        assert (err < 1e-9) == close, (margin, err)


def test_overlapping_windows_cover_every_row_once():
    rows = np.arange(1000.0)[:, None]
    chunks = [rows[i : i + 77] for i in range(0, 1000, 77)]
    seen = []
    for w in iter_overlapping(chunks, 130, 20):
        assert w.lo == max(w.a - 20, 0)
        assert w.lo + w.rows.shape[0] == min(w.b + 20, 1000)
        np.testing.assert_array_equal(w.rows[:, 0], np.arange(w.lo, w.lo + w.rows.shape[0]))
        seen.extend(w.rows[w.centre, 0].tolist())
    assert seen == list(range(1000))
