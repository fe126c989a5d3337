"""Synthetic measurements: inverse dynamics along a trajectory, with the true parameters and noise.

Along a :class:`~manip_id.trajectories.FourierTrajectory` sampled at ``rate``
[Hz] (``t_k = k / rate``, ``k = 0 .. floor(duration * rate)``) the torques are::

    tau(t) = rnea(model(theta), q, dq, ddq) + joint_torques(theta, q, dq[, ddq, temp])

``model(theta)`` is :meth:`Robot.with_parameters` (rigid bodies, and the
armature, which ``pinocchio.rnea`` includes); friction, offset and spring come
from :func:`manip_id.robot.regressor.joint_torques`. None of it goes through the
regressor, so ``regressor(robot, q, dq, ddq) @ theta_true`` reproducing the
simulated torques is an independent check of both.

Noise (seeded, Gaussian, independent per sample and joint)::

    tau_meas_j = tau_j + noise_tau * rms(tau_j) * e,   rms(tau_j) = sqrt(mean_k tau_j(t_k)^2)
    angle_meas_j = angle_j + noise_q * e                [rad or m]
    dq_meas_j = dq_j + noise_dq * e                     [rad/s or m/s]

``noise_tau`` is relative to each joint's noise-free torque RMS over the
record; ``noise_q`` and ``noise_dq`` are absolute (the fields ``tau``, ``q``, ``dq`` of
:class:`MeasurementNoise`). Noise on a continuous
joint's position is added to the angle before it is stored as (cos, sin).
The dataset's ``ddq`` is the exact (analytic) acceleration. The torque, the
position and the velocity noise, and the parameter perturbation, draw from
independent streams of one seed, so switching one on does not change the others.

Temperature. A robot with the ``temperature`` friction law needs the joints' temperature
``T(t)``: :func:`inverse_dynamics` takes it as ``temp`` (a constant, one value per joint,
or one row per sample); :func:`simulate` and :class:`SimulationStream` take a
:class:`ThermalOptions` (a linear drift ``T_j(t) = start + (end - start) t / t_end +
offset_j`` [degC or K], noise-free), whose temperature the dataset carries as ``temp``.
Each stream is drawn per block of :data:`NOISE_BLOCK` samples from its own
generator, so a record is produced block by block (:class:`SimulationStream`,
memory ``8 N nv`` bytes plus one block) with the same samples as :func:`simulate`.

Perturbed parameters (:func:`perturb_parameters`) stay physically consistent:
each body keeps a positive mass and an inertia at the centre of mass that is
positive definite and satisfies the triangle inequalities.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ._checks import as_real
from .datasets import Dataset
from .errors import InputError
from .physics.perturbation import parameter_vector, perturb_parameters, require_physical
from .resources import check_memory
from .robot.model import Robot
from .robot.regressor import joint_torques
from .trajectories import FourierTrajectory, trajectory_to_configuration


@dataclass(frozen=True)
class MeasurementNoise:
    """Gaussian noise on the simulated measurements (module docstring), each >= 0.

    Attributes
    ----------
    tau : float
        Torque noise standard deviation, relative to each joint's noise-free torque RMS.
    q : float
        Position noise standard deviation [rad or m] (on the angle of a continuous joint).
    dq : float
        Velocity noise standard deviation [rad/s or m/s].
    """

    tau: float = 0.0
    q: float = 0.0
    dq: float = 0.0


@dataclass(frozen=True)
class ThermalOptions:
    """The simulated joints' temperature (module docstring): a linear drift.

    Attributes
    ----------
    start, end : float
        Temperature at the first and at the last sample [degC or K] (end None: constant).
    offsets : tuple of float or None
        Per-joint offsets added to every joint's drift [K] (None: none).
    """

    start: float = 25.0
    end: float | None = None
    offsets: tuple[float, ...] | None = None

    def temperature(self, t, t_end: float, nv: int) -> np.ndarray:
        """``T(t)`` [degC or K], shape (len(t), nv), for stamps ``t`` [s] of a record that
        ends at ``t_end`` [s]."""
        end = self.start if self.end is None else float(self.end)
        drift = self.start + (end - self.start) * np.asarray(t, dtype=float) / max(t_end, 1e-300)
        off = np.zeros(nv) if self.offsets is None else np.asarray(self.offsets, dtype=float)
        if off.shape != (nv,):
            raise InputError(f"ThermalOptions.offsets has {off.size} values for nv={nv} joints")
        return drift[:, None] + off


@dataclass(frozen=True)
class SimulatedData:
    """A simulated record and the truth behind it.

    Attributes
    ----------
    dataset : Dataset
        the measurements (noisy ``q``, ``dq``, ``tau``; exact ``ddq``).
    theta_true : numpy.ndarray
        the parameters that produced the torques, shape (p,).
    tau_true : numpy.ndarray
        noise-free torques [N m or N], shape (N, nv).
    noise_tau : float
        torque noise, relative to each joint's torque RMS.
    noise_q : float
        position noise standard deviation [rad or m].
    noise_dq : float
        velocity noise standard deviation [rad/s or m/s].
    perturb : float
        relative perturbation applied to the parameters.
    rate : float
        sampling rate [Hz].
    seed : int
        the seed of every random draw.
    """

    dataset: Dataset
    theta_true: np.ndarray
    tau_true: np.ndarray
    noise_tau: float
    noise_q: float
    noise_dq: float
    perturb: float
    rate: float
    seed: int


def _streams(seed: int) -> list[np.random.Generator]:
    """Independent generators for: parameters, torque noise, position noise, velocity noise."""
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise InputError(f"seed must be a non-negative integer, got {seed!r}")
    return [np.random.default_rng(s) for s in np.random.SeedSequence(int(seed)).spawn(4)]


def _nonnegative(value: float, name: str) -> float:
    return as_real(value, name, minimum=0.0)


def inverse_dynamics(robot: Robot, theta, q, dq, ddq, temp=None) -> np.ndarray:
    """Joint torques of the full model with parameters ``theta``, without the regressor.

    ``pinocchio.rnea`` on ``robot.with_parameters(theta)`` (whose armature is
    zero unless the robot models it) plus :func:`joint_torques` (friction,
    offset, spring).

    Parameters
    ----------
    theta : array_like
        shape (p,); q: (N, nq) [rad or m]; dq, ddq: (N, nv).
    temp : array_like or None
        the joints' temperature [degC or K] of the ``temperature`` law: a scalar, (1,),
        (nv,), (N, 1) or (N, nv) (:func:`~manip_id.robot.regressor.check_temperature`).

    Returns
    -------
    numpy.ndarray
        tau [N m or N], shape (N, nv).
    """
    theta = parameter_vector(robot, theta)
    model = robot.with_parameters(theta)
    data = model.createData()
    n = q.shape[0]
    tau = np.empty((n, robot.nv))
    rnea = pin.rnea
    for k in range(n):
        tau[k] = rnea(model, data, q[k], dq[k], ddq[k])
    if robot.terms.enabled or robot.transmission is not None:  # joint or motor terms
        temp = None if temp is None else _per_sample(temp, n)
        tau += joint_torques(robot, theta, q, dq, ddq, armature=False, temp=temp)  # Ia: rnea
    return tau


def _per_sample(temp, n: int) -> np.ndarray:
    """A constant or per-joint temperature repeated for ``n`` samples, shape (n, k)."""
    t = np.asarray(temp, dtype=float)
    return np.broadcast_to(t.reshape(1, -1), (n, t.size)) if t.ndim < 2 else t


def simulation_bytes(robot: Robot, n_samples: int) -> int:
    """Estimated peak memory [bytes] of :func:`simulate` for ``n_samples`` samples.

    float64 arrays: t (N), angles, dq, ddq, tau_true, tau, the noise draws, dq_meas
    (about 10 N nv) and q, q_meas (2 N nq), plus a copy of each in the dataset checks.
    """
    return int(8 * n_samples * (1 + 10 * robot.nv + 3 * robot.nq) * 2)


def check_simulation_memory(robot: Robot, n_samples: int) -> None:
    """Raise :class:`~manip_id.errors.ResourceError` if the simulation would not fit in memory."""
    need = simulation_bytes(robot, n_samples)
    _check_memory(need, f"a simulation of {n_samples:.3g} samples of {robot.nv} joints needs")


def simulate(
    robot: Robot,
    trajectory: FourierTrajectory,
    *,
    duration: float,
    rate: float,
    theta=None,
    perturb: float = 0.0,
    noise: MeasurementNoise | None = None,
    seed: int = 0,
    thermal: ThermalOptions | None = None,
) -> SimulatedData:
    """Simulated measurements along a trajectory.

    Parameters
    ----------
    robot : Robot
        the robot (its joint terms decide which torques are added).
    trajectory : FourierTrajectory
        joint coordinates per DoF (see :mod:`manip_id.trajectories`).
    duration : float
        length of the record [s].
    rate : float
        sampling rate [Hz]; samples at ``t_k = k / rate``.
    theta : array_like
        true parameters, shape (p,); default the nominal ones.
    perturb : float
        relative perturbation of ``theta`` (see :func:`perturb_parameters`).
    noise : MeasurementNoise, optional
        torque noise relative to each joint's torque RMS, position noise [rad or m] and
        velocity noise [rad/s or m/s] (:class:`MeasurementNoise`); default none.
    seed : int
        seed of every random draw (module docstring).
    thermal : ThermalOptions, optional
        the joints' temperature, carried by the dataset as ``temp`` (needed by the
        ``temperature`` friction law; module docstring); default none.

    Returns
    -------
    SimulatedData
        :class:`SimulatedData` with the dataset and ``theta_true``.
    """
    stream = SimulationStream(
        robot,
        trajectory,
        duration=duration,
        rate=rate,
        theta=theta,
        perturb=perturb,
        noise=noise,
        seed=seed,
        thermal=thermal,
    )
    check_simulation_memory(robot, stream.n_samples)
    return stream.simulated_data()


#: Samples per noise block. The noise of sample ``k`` is drawn from generators of
#: its block ``k // NOISE_BLOCK`` alone, so any range of samples is regenerated
#: exactly, in any order, in any process (:class:`SimulationStream`).
NOISE_BLOCK = 65536


def _block_generator(seed: int, stream: int, block: int) -> np.random.Generator:
    """Generator of one noise stream (1 torque, 2 position, 3 velocity) for one block.

    ``SeedSequence(seed, spawn_key=(stream, block))`` is the ``block``-th child of
    the ``stream``-th child of ``SeedSequence(seed)``: independent of every other
    (stream, block) pair and of the parameter draw (stream 0).
    """
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(stream, block)))


class SimulationStream:
    """A simulated record produced in blocks of samples: memory independent of its length.

    The same measurements as :func:`simulate` (which materializes this stream),
    generated for any sample range ``[start, stop)`` on demand: the trajectory
    and the noise are recomputed per block (noise per :data:`NOISE_BLOCK`
    samples, module docstring); the noise-free torques ``tau_true`` of the
    whole record are computed once, on first use (the torque noise is relative
    to their RMS over the record). Memory: ``8 N nv`` bytes for ``tau_true``
    plus O(NOISE_BLOCK (nq + nv)) per block in flight.

    Parameters are those of :func:`simulate`.

    Attributes
    ----------
    robot, trajectory
        as given.
    theta_true : array_like
        the parameters that produce the torques, shape (p,).
    n_samples
        number of samples ``N = floor(duration rate) + 1``.
    rate : float
        sampling rate [Hz]; sample ``k`` is at ``t_k = k / rate`` [s].
    noise_tau, noise_q, noise_dq, perturb, seed, thermal
        as given (validated).
    """

    def __init__(
        self,
        robot: Robot,
        trajectory: FourierTrajectory,
        *,
        duration: float,
        rate: float,
        theta=None,
        perturb: float = 0.0,
        noise: MeasurementNoise | None = None,
        seed: int = 0,
        thermal: ThermalOptions | None = None,
    ):
        if not isinstance(trajectory, FourierTrajectory):
            raise InputError(f"expected a FourierTrajectory, got {type(trajectory).__name__}")
        if trajectory.nv != robot.nv:
            raise InputError(f"trajectory.nv={trajectory.nv} but robot.nv={robot.nv}")
        try:
            duration, rate = float(duration), float(rate)
        except (TypeError, ValueError) as exc:
            raise InputError(
                f"duration [s] and rate [Hz] must be numbers, got {duration!r} and {rate!r}"
            ) from exc
        if not (math.isfinite(duration) and duration > 0):
            raise InputError(f"duration must be a positive time [s], got {duration}")
        if not (math.isfinite(rate) and rate > 0):
            raise InputError(f"rate must be a positive sampling rate [Hz], got {rate}")
        n = int(math.floor(duration * rate + 1e-9)) + 1
        if n < 2:
            raise InputError(f"duration * rate = {duration * rate:g} gives fewer than 2 samples")
        self.robot = robot
        self.trajectory = trajectory
        self.n_samples = n
        self.rate = rate  # [Hz]
        self.perturb = _nonnegative(perturb, "perturb")
        noise = MeasurementNoise() if noise is None else noise
        self.noise_tau = _nonnegative(noise.tau, "noise.tau")  # relative
        self.noise_q = _nonnegative(noise.q, "noise.q")  # [rad or m]
        self.noise_dq = _nonnegative(noise.dq, "noise.dq")  # [rad/s or m/s]
        self.seed = int(seed)
        self.thermal = thermal
        base = robot.nominal_parameters if theta is None else parameter_vector(robot, theta)
        require_physical(robot, base)
        g_theta = _streams(self.seed)[0]
        self.theta_true = perturb_parameters(
            robot, self.perturb, seed=int(g_theta.integers(2**63)), theta=base
        )
        self._tau_true: np.ndarray | None = None
        self._rms: np.ndarray | None = None

    @property
    def nbytes(self) -> int:
        """Memory [bytes] the stream keeps: ``tau_true`` (N, nv) float64."""
        return 8 * self.n_samples * self.robot.nv

    def _noise_free(self, start: int, stop: int):
        """t [s], angles, q, dq, ddq of samples ``[start, stop)`` without noise."""
        t = np.arange(start, stop) / self.rate  # [s]
        angles, dq, ddq = self.trajectory.sample(t)
        return t, angles, trajectory_to_configuration(self.robot, angles), dq, ddq

    def temperature(self, start: int = 0, stop: int | None = None) -> np.ndarray | None:
        """The joints' temperature of samples ``[start, stop)`` [degC or K], (n, nv), or
        None without :class:`ThermalOptions`."""
        if self.thermal is None:
            return None
        start, stop = self._range(start, stop)
        t_end = (self.n_samples - 1) / self.rate  # [s]
        return self.thermal.temperature(np.arange(start, stop) / self.rate, t_end, self.robot.nv)

    @property
    def tau_true(self) -> np.ndarray:
        """Noise-free torques of the whole record [N m or N], shape (N, nv) (computed once)."""
        if self._tau_true is None:
            _check_memory(
                self.nbytes, f"the noise-free torques of {self.n_samples:.3g} samples need"
            )
            tau = np.empty((self.n_samples, self.robot.nv))  # [N m or N]
            batch = _BatchInverseDynamics(self.robot, self.theta_true)
            blocks = self.robot.evaluator.sequential(range(0, self.n_samples, NOISE_BLOCK))
            for lo in blocks:  # one path: the hysteresis state carries from block to block
                hi = min(lo + NOISE_BLOCK, self.n_samples)
                _, _, q, dq, ddq = self._noise_free(lo, hi)
                tau[lo:hi] = batch(q, dq, ddq, self.temperature(lo, hi))
            self._tau_true = tau
        return self._tau_true

    @property
    def tau_rms(self) -> np.ndarray:
        """RMS of each joint's noise-free torque over the record [N m or N], shape (nv,)."""
        if self._rms is None:
            tau = self.tau_true
            sumsq = np.zeros(self.robot.nv)  # [(N m)^2 or N^2], per block: no (N, nv) temporary
            for lo in range(0, self.n_samples, NOISE_BLOCK):
                block = tau[lo : lo + NOISE_BLOCK]
                sumsq += np.einsum("ij,ij->j", block, block)
            self._rms = np.sqrt(sumsq / self.n_samples)
        return self._rms

    def _range(self, start: int, stop: int | None) -> tuple[int, int]:
        stop = self.n_samples if stop is None else int(stop)
        start = int(start)
        if not 0 <= start <= stop <= self.n_samples:
            raise InputError(f"sample range [{start}, {stop}) is not within [0, {self.n_samples}]")
        return start, stop

    def _noise(self, stream: int, block: int, lo: int, hi: int, width: int) -> np.ndarray:
        """Standard normal draws of samples ``[lo, hi)`` of ``block``, shape (hi - lo, width)."""
        first = block * NOISE_BLOCK
        size = min(NOISE_BLOCK, self.n_samples - first)
        e = _block_generator(self.seed, stream, block).standard_normal((size, width))
        return e[lo - first : hi - first]

    def measurements(self, start: int = 0, stop: int | None = None):
        """Measured samples of ``[start, stop)``, one :data:`NOISE_BLOCK` (or less) at a time.

        Yields
        ------
        object : array_like
            ``(t, q, dq, ddq, tau)``: t [s] of shape (n,), q (n, nq) [rad or m]
            (noisy), dq (n, nv) (noisy), ddq (n, nv) (exact), tau (n, nv) [N m or N]
            (noisy), with ``n <= NOISE_BLOCK``.
        """
        start, stop = self._range(start, stop)
        nv = self.robot.nv
        if stop <= start:
            return
        for block in range(start // NOISE_BLOCK, (stop - 1) // NOISE_BLOCK + 1):
            lo = max(start, block * NOISE_BLOCK)
            hi = min(stop, (block + 1) * NOISE_BLOCK)
            t, angles, q, dq, ddq = self._noise_free(lo, hi)
            tau = self.tau_true[lo:hi]
            if self.noise_tau > 0:
                tau = tau + self.noise_tau * self.tau_rms * self._noise(1, block, lo, hi, nv)
            if self.noise_q > 0:
                noisy = angles + self.noise_q * self._noise(2, block, lo, hi, nv)  # [rad or m]
                q = trajectory_to_configuration(self.robot, noisy)
            if self.noise_dq > 0:
                dq = dq + self.noise_dq * self._noise(3, block, lo, hi, nv)  # [rad/s or m/s]
            yield t, q, dq, ddq, tau

    def blocks(self, start: int = 0, stop: int | None = None):
        """``(q, dq, ddq, tau)`` blocks of ``[start, stop)`` (``(q, dq, ddq, tau, None,
        temp)`` with :class:`ThermalOptions`), as
        :func:`manip_id.identification.identify` takes them."""
        at = self._range(start, stop)[0]
        for _, q, dq, ddq, tau in self.measurements(start, stop):
            temp = self.temperature(at, at + q.shape[0])
            at += q.shape[0]
            yield (q, dq, ddq, tau) if temp is None else (q, dq, ddq, tau, None, temp)

    def parts(self, n_parts: int, start: int = 0, stop: int | None = None) -> list:
        """``[(self.blocks, (lo, hi)), ...]``: ``[start, stop)`` cut into ``n_parts`` contiguous
        ranges, for ``identify(..., workers > 1)`` (each part simulated in its process)."""
        start, stop = self._range(start, stop)
        self.tau_true  # noqa: B018 (computed once, before the workers fork)
        edges = np.linspace(start, stop, max(int(n_parts), 1) + 1).round().astype(int)
        pairs = zip(edges[:-1], edges[1:], strict=True)
        return [(self.blocks, (int(a), int(b))) for a, b in pairs if b > a]

    def meta(self) -> dict:
        """The ``meta`` of the simulated :class:`~manip_id.datasets.Dataset`."""
        return {
            "source": "simulation",
            "robot": self.robot.name,
            "perturb": self.perturb,
            "noise_tau": self.noise_tau,
            "noise_q": self.noise_q,
            "noise_dq": self.noise_dq,
            "rate": self.rate,
            "seed": self.seed,
            "period": float(self.trajectory.period),  # [s] the motion repeats after it
        }

    def dataset(self, start: int = 0, stop: int | None = None) -> Dataset:
        """The samples ``[start, stop)`` as one :class:`~manip_id.datasets.Dataset`."""
        start, stop = self._range(start, stop)
        n, robot = stop - start, self.robot
        t = np.empty(n)
        q = np.empty((n, robot.nq))
        dq, ddq, tau = (np.empty((n, robot.nv)) for _ in range(3))
        at = 0
        for bt, bq, bdq, bddq, btau in self.measurements(start, stop):
            k = bt.shape[0]
            t[at : at + k], q[at : at + k], dq[at : at + k] = bt, bq, bdq
            ddq[at : at + k], tau[at : at + k] = bddq, btau
            at += k
        return Dataset(
            t=t,
            q=q,
            dq=dq,
            tau=tau,
            ddq=ddq,
            joint_names=tuple(robot.dof_names),
            meta=self.meta(),
            temp=self.temperature(start, stop),
        )

    def simulated_data(self) -> SimulatedData:
        """The whole record as :class:`SimulatedData` (what :func:`simulate` returns)."""
        return SimulatedData(
            dataset=self.dataset(),
            theta_true=self.theta_true,
            tau_true=self.tau_true,
            noise_tau=self.noise_tau,
            noise_q=self.noise_q,
            noise_dq=self.noise_dq,
            perturb=self.perturb,
            rate=self.rate,
            seed=self.seed,
        )


class _BatchInverseDynamics:
    """:func:`inverse_dynamics` of a block of samples in one native call.

    ``pinocchio.rneaInParallel`` (one thread) evaluates RNEA for every column of
    (nq, n) / (nv, n) arrays without a Python-level call per sample: about half
    the time of the per-sample loop. Falls back to :func:`inverse_dynamics` where
    the Pinocchio build lacks it. Joint terms come from :func:`joint_torques`.
    """

    def __init__(self, robot: Robot, theta: np.ndarray):
        self.robot, self.theta = robot, theta
        self.pool = None
        if hasattr(pin, "rneaInParallel") and hasattr(pin, "ModelPool"):
            self.pool = pin.ModelPool(robot.with_parameters(theta), 1)

    def __call__(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, temp=None) -> np.ndarray:
        if self.pool is None:
            return inverse_dynamics(self.robot, self.theta, q, dq, ddq, temp)
        out = np.empty((self.robot.nv, q.shape[0]), order="F")  # [N m or N], sample per column
        pin.rneaInParallel(1, self.pool, q.T, dq.T, ddq.T, out)
        tau = out.T
        if self.robot.terms.enabled or self.robot.transmission is not None:  # Ia: in rnea
            tau = tau + joint_torques(self.robot, self.theta, q, dq, ddq, armature=False, temp=temp)
        return tau


def _check_memory(need: int, what: str) -> None:
    """:func:`~manip_id.resources.check_memory` with the simulation's hint."""
    check_memory(need, what, "shorten the duration or lower the rate")


__all__ = [
    "NOISE_BLOCK",
    "MeasurementNoise",
    "SimulatedData",
    "SimulationStream",
    "ThermalOptions",
    "inverse_dynamics",
    "simulate",
]
