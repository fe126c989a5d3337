"""Figures: valid PNGs of the expected size, the drawn data are the given data, bad input."""

from __future__ import annotations

import matplotlib.image as mpimg
import numpy as np
import pytest

from manip_id.errors import InputError
from manip_id.viz import figures
from manip_id.viz.figures import DPI, png_size

RNG = np.random.default_rng(0)
N, NJ = 300, 4
T = np.linspace(0.0, 3.0, N)
TAU = np.sin(np.outer(T, np.arange(1, NJ + 1)))
PRED = TAU + 0.01 * RNG.standard_normal(TAU.shape)
NAMES = [f"j{i}" for i in range(NJ)]


def _check_png(path, fig):
    """The file is a PNG of exactly figsize * dpi pixels, and not a blank image."""
    assert path.is_file()
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    w, h = png_size(path)
    expected = np.round(fig.get_size_inches() * DPI).astype(int)
    assert (w, h) == tuple(expected)
    pixels = mpimg.imread(str(path))  # independent decoder (matplotlib's PNG reader)
    assert pixels.shape[:2] == (h, w)
    assert pixels[..., :3].std() > 0.01  # something drawn
    assert not list(path.parent.glob(".*"))  # no temporary file left


def _lines(ax, label):
    return [ln for ln in ax.get_lines() if ln.get_label() == label]


def test_torque_fit_one_axes_per_joint_with_the_given_data(tmp_path):
    tv = T + 3.01
    path = tmp_path / "fit.png"
    fig = figures.torque_fit(
        path,
        T,
        TAU,
        PRED,
        t_validation=tv,
        tau_validation=TAU,
        tau_validation_pred=PRED,
        options=figures.FigureOptions(title="torque fit: test", joint_names=NAMES),
    )
    _check_png(path, fig)
    axes = fig.get_axes()
    assert len(axes) == NJ
    for j, ax in enumerate(axes):
        (meas,) = _lines(ax, "measured (training)")
        (pred,) = _lines(ax, "predicted (training)")
        np.testing.assert_array_equal(meas.get_ydata(), TAU[:, j])
        np.testing.assert_array_equal(pred.get_ydata(), PRED[:, j])
        assert _lines(ax, "predicted (validation)")
        assert NAMES[j] in ax.get_ylabel() and "[N m]" in ax.get_ylabel()
    assert axes[-1].get_xlabel() == "time [s]"
    assert fig._suptitle.get_text() == "torque fit: test"


def test_long_signals_are_strided(tmp_path):
    n = figures.MAX_POINTS * 3 + 7
    t = np.linspace(0, 1, n)
    fig = figures.residuals(tmp_path / "r.png", t, np.sin(t)[:, None])
    (line,) = [ln for ln in fig.get_axes()[0].get_lines() if "training" in ln.get_label()]
    assert len(line.get_xdata()) <= figures.MAX_POINTS
    np.testing.assert_array_equal(line.get_xdata(), t[:: int(np.ceil(n / figures.MAX_POINTS))])


def test_residuals_rms_in_legend(tmp_path):
    res = TAU - PRED
    fig = figures.residuals(tmp_path / "res.png", T, res, joint_names=NAMES, units="N")
    _check_png(tmp_path / "res.png", fig)
    assert len(fig.get_axes()) == NJ
    for j, ax in enumerate(fig.get_axes()):
        (line,) = [ln for ln in ax.get_lines() if ln.get_label().startswith("training")]
        rms = np.sqrt(np.mean(res[:, j] ** 2))
        assert line.get_label() == f"training, RMS {rms:.3g}"


@pytest.mark.parametrize("n_zero", [0, 3])
def test_singular_values_split_at_the_threshold(tmp_path, n_zero):
    s = np.concatenate([np.logspace(0, -4, 10), np.full(n_zero, 1e-14)])
    tol = 1e-8
    fig = figures.singular_values(tmp_path / "sv.png", s[::-1], tolerance=tol, title="sv")
    _check_png(tmp_path / "sv.png", fig)
    (ax,) = fig.get_axes()
    above = [ln for ln in ax.get_lines() if ln.get_label().startswith("above")]
    below = [ln for ln in ax.get_lines() if ln.get_label().startswith("below")]
    assert len(above[0].get_xdata()) == 10
    np.testing.assert_allclose(above[0].get_ydata(), s[:10] / s[0])
    assert len(below) == (1 if n_zero else 0)
    (thr,) = [ln for ln in ax.get_lines() if ln.get_label().startswith("rank threshold")]
    assert thr.get_ydata()[0] == tol
    assert ax.get_yscale() == "log"


def test_parameter_history_shows_the_moving_parameters_with_truth(tmp_path):
    k, p = 200, 8
    t = np.linspace(0, 2, k)
    th = np.ones((k, p))
    th[:, 2] = 1 + (1 - np.exp(-t))  # moves by 0.86
    th[:, 5] = 1 - 0.5 * (1 - np.exp(-t))  # moves by 0.43
    true = np.ones(p)
    true[2], true[5] = 2.0, 0.5
    names = [f"b.p{i}" for i in range(p)]
    units = ["kg"] * p
    fig = figures.parameter_history(
        tmp_path / "ph.png", t, th, names=names, units=units, theta_true=true, max_parameters=2
    )
    _check_png(tmp_path / "ph.png", fig)
    axes = fig.get_axes()
    assert [ax.get_title() for ax in axes] == ["b.p2", "b.p5"]
    for ax, i in zip(axes, (2, 5), strict=True):
        (truth,) = _lines(ax, "true")
        assert truth.get_ydata()[0] == true[i]
        assert "[kg]" in ax.get_ylabel()
    assert "2 of 8 parameters" in fig._suptitle.get_text()


def test_tracking_error_norm_and_baseline(tmp_path):
    err = 0.1 * np.exp(-T)[:, None] * np.ones(NJ)
    fig = figures.tracking_error(tmp_path / "te.png", T, err, joint_names=NAMES, baseline=2 * err)
    _check_png(tmp_path / "te.png", fig)
    top, bottom = fig.get_axes()
    assert len(top.get_lines()) == NJ
    (ad,) = _lines(bottom, "adaptive")
    (fx,) = _lines(bottom, "fixed parameters")
    np.testing.assert_allclose(ad.get_ydata(), np.linalg.norm(err, axis=1))
    np.testing.assert_allclose(fx.get_ydata(), 2 * np.linalg.norm(err, axis=1))


def test_trajectory_limits_reports_the_range_used(tmp_path):
    q = 0.5 * np.sin(np.outer(T, np.ones(3)))
    lo, hi = -np.ones(3), np.array([1.0, 1.0, np.inf])
    fig = figures.trajectory_limits(tmp_path / "tr.png", T, q, lower=lo, upper=hi)
    _check_png(tmp_path / "tr.png", fig)
    axes = fig.get_axes()
    assert len(axes) == 3
    used = (q[:, 0].max() - q[:, 0].min()) / 2.0
    assert axes[0].get_title() == f"joint 1: {100 * used:.0f} % of the range used"
    assert axes[2].get_title() == "joint 3: no finite limits"
    assert _lines(axes[0], "limits") and not _lines(axes[2], "limits")


BAD = [
    (figures.torque_fit, (T, TAU, PRED[:, :2]), {}, "tau_pred.shape=(300, 2)"),
    (figures.torque_fit, (T[:-1], TAU, PRED), {}, "t.shape=(299,)"),
    (
        figures.torque_fit,
        (T, TAU, PRED),
        {"options": figures.FigureOptions(joint_names=["a"])},
        "1 joint names given for 4",
    ),
    (figures.torque_fit, (T, TAU, PRED), {"t_validation": T}, "validation needs"),
    (figures.residuals, (T, np.full((N, 2), np.nan)), {}, "residual"),
    (figures.singular_values, (np.array([1.0, -1.0]),), {"tolerance": 1e-6}, ">= 0"),
    (figures.singular_values, (np.ones(3),), {"tolerance": 2.0}, "tolerance"),
    (
        figures.parameter_history,
        (T, TAU),
        {"names": NAMES, "theta_true": np.ones(3)},
        "theta_true.shape=(3,)",
    ),
    (figures.tracking_error, (T, TAU), {"baseline": TAU[:, :1]}, "baseline.shape=(300, 1)"),
    (
        figures.trajectory_limits,
        (T, TAU),
        {"lower": np.zeros(3), "upper": np.ones(4)},
        "lower.shape=(3,)",
    ),
]


@pytest.mark.parametrize(("fn", "args", "kwargs", "message"), BAD)
def test_bad_input_is_an_input_error_and_writes_nothing(tmp_path, fn, args, kwargs, message):
    path = tmp_path / "out.png"
    path.write_bytes(b"old")
    with pytest.raises(InputError, match=None) as info:
        fn(path, *args, **kwargs)
    assert message in str(info.value)
    assert path.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.png"]


def test_png_size_rejects_non_png(tmp_path):
    bad = tmp_path / "x.png"
    bad.write_bytes(b"not a png at all, not even close")
    with pytest.raises(InputError, match="not a PNG"):
        png_size(bad)
