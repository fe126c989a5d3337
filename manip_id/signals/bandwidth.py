"""The cut-off a log asks for: its motion's bandwidth from the velocity power spectrum.

``cutoff = "auto"`` (``--cutoff auto``) chooses the low-pass cut-off of the
preprocessing from the positions of the log itself:

1. the velocity of each joint by first differences of the positions,
   ``v_k = (q_{k+1} - q_k) / (t_{k+1} - t_k)``;
2. its power spectrum by Welch's method: Hann-windowed segments of
   :data:`SEGMENT_SECONDS` seconds (the whole log when shorter), mean removed,
   periodograms summed over the segments (memory: one segment, whatever the length);
3. the noise floor of each joint: white position noise (encoders, quantisation) gives the
   differenced velocity a power ``c_j sin^2(pi f / rate)``; ``c_j`` is the median of
   ``P_j(f) / sin^2(pi f / rate)`` over the upper half of the band ``f > rate / 4`` (where
   a robot's motion has no power). A frequency counts as motion only where its power
   exceeds :data:`NOISE_MARGIN` (10) times the floor, and then with the floor subtracted
   (a chi-square periodogram bin passes that margin by chance with probability ~1e-3);
4. the bandwidth ``f_99,j``: the lowest frequency below which :data:`POWER_FRACTION`
   (99 %) of the remaining power of joint ``j`` lies; the log's bandwidth is the
   largest over the joints, leaving out (and naming) a joint whose ``f_99`` exceeds
   :data:`OUTLIER` (10) times the median joint's: its motion is too small against its
   noise for the floor model (the real Panda log's joint 3, whose stamps jitter);
5. ``cutoff = FACTOR * bandwidth`` (:data:`FACTOR` = 3: a zero-phase Butterworth of order
   4 passes ``f_99`` with a gain of ``1 - 3^-8``), raised to :data:`MIN_CUTOFF` (20 Hz) and
   capped at ``rate / (5 decimate)`` (0.4 times the Nyquist frequency of the kept
   samples).

The choice is printed with its reason (:attr:`CutoffChoice.reason`) and kept in the
preprocessing record of each file (``preprocess.cutoff_reason`` of the JSON).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import DataError

#: Length of one Welch segment [s].
SEGMENT_SECONDS = 10.0
#: Share of a joint's velocity power below its bandwidth [-].
POWER_FRACTION = 0.99
#: Cut-off over bandwidth [-].
FACTOR = 3.0
#: Lowest cut-off chosen [Hz]: the torques' Coulomb steps and the regressor's sign(dq)
#: columns are wider-band than the motion; below ~20 Hz the filter's smearing of them
#: exceeds 1 % torque noise on the simulated coupled wrist (tests/test_transmission.py).
MIN_CUTOFF = 20.0
#: A joint whose bandwidth is this many times the median joint's is noise-dominated [-].
OUTLIER = 10.0
#: Power over the noise floor a frequency needs to count as motion [-].
NOISE_MARGIN = 10.0


@dataclass(frozen=True)
class CutoffChoice:
    """A cut-off chosen from a log (module docstring).

    Attributes
    ----------
    cutoff : float
        The cut-off [Hz].
    rate : float
        The log's sampling rate [Hz].
    bandwidth : numpy.ndarray
        ``f_99`` per joint [Hz], shape (nv,).
    reason : str
        One line saying how the cut-off was chosen.
    """

    cutoff: float
    rate: float
    bandwidth: np.ndarray
    reason: str


class VelocitySpectrum:
    """Welch's velocity power spectrum of a log, accumulated block by block (module docstring).

    ``add(t, q)`` takes consecutive rows (t: (k,) [s], q: (k, nv) [rad or m]);
    :meth:`choose` gives the :class:`CutoffChoice`.
    """

    def __init__(self, nv: int):
        self.nv = nv
        self._t: list[np.ndarray] = []
        self._q: list[np.ndarray] = []
        self._held = 0
        self._length: int | None = None  # samples per segment, from the first rows' rate
        self.power: np.ndarray | None = None  # summed periodograms (n_freq, nv)
        self.segments = 0
        self._dt_sum, self._dt_n = 0.0, 0

    def add(self, t: np.ndarray, q: np.ndarray) -> None:
        """Take the next rows (positions of every joint)."""
        if not len(t):
            return
        self._t.append(np.asarray(t, dtype=float))
        self._q.append(np.asarray(q, dtype=float))
        self._held += len(t)
        if self._length is None and self._held >= 2:
            tt = np.concatenate(self._t)
            step = float(np.median(np.diff(tt)))
            if step > 0:
                self._length = max(int(round(SEGMENT_SECONDS / step)), 16)
        while self._length is not None and self._held >= self._length + 1:
            tt, qq = np.concatenate(self._t), np.concatenate(self._q)
            n = self._length + 1  # rows of one segment of `length` differences
            self._segment(tt[:n], qq[:n])
            self._t, self._q = [tt[n - 1 :]], [qq[n - 1 :]]  # the last row starts the next
            self._held = len(tt) - n + 1

    def _segment(self, t: np.ndarray, q: np.ndarray) -> None:
        dt = np.diff(t)
        v = np.diff(q, axis=0) / dt[:, None]  # [rad/s or m/s]
        v -= v.mean(axis=0)
        w = np.hanning(v.shape[0])[:, None]
        p = np.abs(np.fft.rfft(v * w, axis=0)) ** 2
        if self.power is None or self.power.shape != p.shape:
            if self.power is not None:  # the short rest of a log: not a whole segment
                return
            self.power = np.zeros_like(p)
        self.power += p
        self.segments += 1
        self._dt_sum += float(dt.sum())
        self._dt_n += dt.size

    def choose(self, decimate: int = 1, names=None) -> CutoffChoice:
        """The cut-off of the rows seen (module docstring); ``names``: one per joint."""
        if self.segments == 0 and self._held >= 8:  # shorter than one segment: all of it
            self._segment(np.concatenate(self._t), np.concatenate(self._q))
        if self.power is None:
            raise DataError("cannot choose a cut-off: the log has fewer than 8 samples")
        rate = self._dt_n / self._dt_sum  # [Hz]
        n_freq = self.power.shape[0]
        freq = np.arange(n_freq) * rate / (2 * (n_freq - 1)) if n_freq > 1 else np.zeros(1)
        upper = freq > rate / 4
        shape = np.sin(np.pi * freq / rate) ** 2  # white position noise, differenced
        level = (
            np.median(self.power[upper] / shape[upper, None], axis=0)
            if upper.any()
            else np.zeros(self.nv)
        )
        floor = shape[:, None] * level  # (n_freq, nv)
        motion = np.where(self.power > NOISE_MARGIN * floor, self.power - floor, 0.0)
        motion[0] = 0.0  # the mean (removed)
        total = motion.sum(axis=0)
        bandwidth = np.zeros(self.nv)
        for j in range(self.nv):
            if total[j] > 0:
                k = int(np.searchsorted(np.cumsum(motion[:, j]), POWER_FRACTION * total[j]))
                bandwidth[j] = freq[min(k, n_freq - 1)]
        names = list(names) if names is not None else [f"joint {j + 1}" for j in range(self.nv)]
        cap = rate / (5.0 * max(int(decimate), 1))
        if not total.any():
            return CutoffChoice(
                min(MIN_CUTOFF, cap), rate, bandwidth, "auto: no motion above the noise floor"
            )
        # a joint whose f_99 is OUTLIER times the median joint's is noise-dominated (its
        # motion too small for the floor model, e.g. stamps with jitter): left out
        med = float(np.median(bandwidth[total > 0]))
        noisy = [names[k] for k in range(self.nv) if bandwidth[k] > OUTLIER * max(med, 0.1)]
        kept = np.where([n in noisy for n in names], -np.inf, bandwidth)
        j = int(np.argmax(kept))
        bw = float(bandwidth[j])
        raw = FACTOR * bw
        cutoff = min(max(raw, MIN_CUTOFF), cap)
        why = (
            f"auto: {POWER_FRACTION:.0%} of each joint's velocity power lies below "
            f"{bw:.3g} Hz ({names[j]} the highest, {rate:.4g} Hz log)"
        )
        if noisy:
            why += f"; noise-dominated, left out: {', '.join(noisy)}"
        if cutoff == raw:
            why += f"; cut-off {FACTOR:g} x that = {cutoff:.3g} Hz"
        elif cutoff == cap:
            why += f"; cut-off capped at rate / {5 * max(int(decimate), 1)} = {cutoff:.3g} Hz"
        else:
            why += f"; cut-off raised to the minimum {cutoff:.3g} Hz"
        return CutoffChoice(cutoff, rate, bandwidth, why)


def choose_cutoff(t, q, *, decimate: int = 1, names=None) -> CutoffChoice:
    """The cut-off for a log held in memory: ``t`` (N,) [s], ``q`` (N, nv) (module docstring)."""
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or t.shape != (q.shape[0],):
        raise DataError(f"choose_cutoff needs t (N,) and q (N, nv), got {t.shape} and {q.shape}")
    spec = VelocitySpectrum(q.shape[1])
    spec.add(t, q)
    return spec.choose(decimate, names)
