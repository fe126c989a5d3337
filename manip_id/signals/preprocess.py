"""From a raw log to data fit for identification, in memory: :func:`preprocess`.

The steps and the math are those of :mod:`manip_id.signals`; the streamed, blocked form
of the same steps is :func:`manip_id.signals.preprocess_blocks`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

from ..datasets import Dataset
from ..errors import InputError
from .filters import DEFAULT_CUTOFF, DEFAULT_ORDER, Lowpass
from .sampling import (
    derivative,
    downsample,
    is_uniform,
    resample_dataset,
    sampling_rate,
    trim_samples,
)


@dataclass(frozen=True)
class PreprocessSettings:
    """What :func:`preprocess` did, kept in ``dataset.meta["preprocess"]``."""

    cutoff: float
    order: int
    rate: float
    resampled: bool
    velocity: str
    filter_torque: bool
    trim: int
    decimate: int
    #: how the cut-off was chosen ("" : given; see :mod:`~manip_id.signals.bandwidth`)
    cutoff_reason: str = ""


@dataclass(frozen=True)
class SignalOptions:
    """How :func:`~manip_id.signals.preprocess_blocks` cleans a stream (the options of
    :func:`preprocess`, one object).

    Attributes
    ----------
    cutoff : float
        Low-pass cut-off [Hz].
    order : int
        Butterworth order of the one-way filter.
    rate : float or None
        Rate of the uniform grid [Hz]; None: the mean rate.
    decimate : int
        Keep every ``decimate``-th sample after filtering.
    trim : float or None
        Seconds removed at each end; None: the filter's edge transient.
    velocity : str
        ``"measured"`` (filter the logged dq) or ``"differentiate"`` (dq from q).
    filter_torque : bool
        Low-pass the torques with the same filter.
    """

    cutoff: float = DEFAULT_CUTOFF
    order: int = DEFAULT_ORDER
    rate: float | None = None
    decimate: int = 1
    trim: float | None = None
    velocity: str = "measured"
    filter_torque: bool = True

    def __post_init__(self):
        if self.velocity not in ("measured", "differentiate"):
            raise InputError(
                f"velocity must be 'measured' or 'differentiate', got {self.velocity!r}"
            )


def preprocess_plan(
    fs: float, resampled: bool, options: SignalOptions
) -> tuple[Lowpass, PreprocessSettings]:
    """The checked decimation, the filter and the settings of :func:`preprocess` and
    :func:`~manip_id.signals.preprocess_blocks` at the rate ``fs`` [Hz] of the
    (resampled) data."""
    decimate, cutoff = options.decimate, options.cutoff
    if int(decimate) != decimate or decimate < 1:
        raise InputError(f"decimation factor must be a positive integer, got {decimate}")
    if decimate > 1 and cutoff >= fs / (2 * decimate):
        raise InputError(
            f"cut-off {cutoff} Hz is not below the Nyquist frequency {fs / (2 * decimate):g} Hz "
            f"after decimating {fs:g} Hz by {decimate}: the result would alias"
        )
    filt = Lowpass(cutoff, fs, options.order)
    trim = options.trim
    n_trim = filt.transient_samples() if trim is None else int(round(float(trim) * fs))
    settings = PreprocessSettings(
        cutoff=filt.cutoff,
        order=filt.order,
        rate=fs,
        resampled=resampled,
        velocity=options.velocity,
        filter_torque=options.filter_torque,
        trim=n_trim,
        decimate=int(decimate),
    )
    return filt, settings


def preprocess(
    dataset: Dataset,
    *,
    cutoff: float = DEFAULT_CUTOFF,
    order: int = DEFAULT_ORDER,
    rate: float | None = None,
    decimate: int = 1,
    trim: float | None = None,
    velocity: str = "measured",
    filter_torque: bool = True,
) -> Dataset:
    """Clean a measured dataset for identification; the result has ``ddq`` filled.

    Steps: (1) when the time stamps are not uniform (or ``rate`` is given),
    cubic-spline resampling on the grid ``t[0] + k / rate``
    (default rate: the mean one); (2) zero-phase
    Butterworth low-pass (``cutoff`` [Hz], ``order``) of q, dq, the temperature
    (when measured) and, with ``filter_torque``, tau; (3) ``ddq`` by central
    differences of the filtered dq; (4) removal of the filter's edge transients,
    ``trim`` seconds at each end; (5) keeping every ``decimate``-th sample.

    Parameters
    ----------
    dataset : Dataset
        measurements (ddq, if present, is replaced)
    cutoff : float
        low-pass cut-off [Hz]. The default 3 Hz was chosen on the real
        Panda log (Fourier excitation up to 0.375 Hz, about 1 kHz): with 64 base
        parameters identified on its first 70 % (each part preprocessed alone,
        1 s trimmed at each end), the validation torque error is flat from 2 to
        5 Hz (0.75, 0.74, 0.76 %) and grows outside: 1.68 % at 1 Hz (the filter
        bites the motion's harmonics and velocity ramps), 1.07 % at 10 Hz and
        2.60 % at 20 Hz (differentiated noise in ddq, torque noise in the
        reference). See ``experiments/panda_real.py``.
    order : int
        Butterworth order (forward-backward: twice the attenuation).
    rate : float, optional
        sampling rate of the uniform grid [Hz]; default the mean rate
        (:func:`sampling_rate`).
    decimate : int
        keep every ``decimate``-th sample after filtering; needs
        ``cutoff < rate / (2 decimate)``.
    trim : float, optional
        seconds removed at each end; default the edge transient of the
        filter (:meth:`Lowpass.transient_samples`).
    velocity : str
        ``"measured"`` filters the logged dq; ``"differentiate"``
        replaces it by the central-difference derivative of the filtered q.
    filter_torque : bool
        low-pass the torques with the same filter (default). Turn
        it off to parallel-filter them with the regressor instead
        (:func:`filter_regressor`).

    Returns
    -------
    Dataset
        A new :class:`Dataset` on the uniform grid with ``ddq`` [rad/s^2]; its
        ``meta["preprocess"]`` holds the :class:`PreprocessSettings` used.
    """
    options = SignalOptions(cutoff, order, rate, decimate, trim, velocity, filter_torque)
    uniform = is_uniform(dataset.t)
    resampled = rate is not None or not uniform
    data = resample_dataset(dataset, rate) if resampled else dataset
    fs = sampling_rate(data.t) if not resampled else float(data.meta["rate"])
    filt, settings = preprocess_plan(fs, resampled, options)
    n_trim = settings.trim
    q = filt(data.q)
    if velocity == "differentiate":
        dq = derivative(data.t, q)
    else:
        dq = filt(data.dq)
    ddq = derivative(data.t, dq)
    tau = filt(data.tau) if filter_torque else data.tau
    temp = None if data.temp is None else filt(data.temp)  # like q: slow, zero phase
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the degrees check already ran on the input
        out = replace(data, q=q, dq=dq, ddq=ddq, tau=tau, temp=temp)
    out = trim_samples(out, n_trim)
    out = downsample(out, decimate)
    return replace(out, meta={**dataset.meta, "preprocess": settings})
