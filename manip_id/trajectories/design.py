"""``design_excitation``: a safe, informative motion at rest at both ends (the front door).

The motion is a :class:`~.rest.RestFourier` series of period ``1 / base_frequency``
repeated over ``duration``. Steps:

1. global start: ``options.starts`` random coefficient vectors, each scaled about the
   start pose to fit the linear limits (and shrunk until torques and clearance hold);
2. local refinement: SLSQP on the criterion (:mod:`.information`, exact gradient) from
   the ``options.refine`` best starts, under the constraints of :mod:`.constraints`
   (a working set of the rows near their bound, re-screened until all hold:
   :mod:`.working_set`);
3. verification on the run's own grid (``rate``): :func:`.verify.verify_design`; a
   trajectory that leaves a limit between the optimizer's grid times is shrunk about
   the start pose until it passes, else the binding constraint is raised.

Sampling density: the criterion uses ``10 L`` times per period (``L`` harmonics: the
information is a periodic integral of products of the regressor's entries, whose
velocity products reach ``4 L`` harmonics, and an equally spaced sum of ``n`` samples
integrates a trigonometric polynomial of degree below ``n`` exactly; on the panda's 20 s
designs the criterion on ``8 L`` to ``80 L`` samples agrees to 0.05), the constraints
``20 L + 1`` times (with the between-samples slacks of :mod:`.constraints`), the
clearance ``80 L + 1`` times (its between-samples allowance grows with the spacing).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pinocchio as pin

from .._checks import random_generator
from ..errors import InfeasibleTrajectoryError, InputError, RobotError
from ..identifiability import analyze
from ..resources import MAX_STEPS, check_count
from ..robot.model import Robot
from .constraints import Bounds, ClearanceConstraint, TorqueConstraint, linear_constraints
from .fourier import FourierTrajectory, dof_layout, trajectory_to_configuration
from .identified_torque import IdentifiedTorques, UncertainTorqueConstraint
from .information import CRITERIA, InformationModel, criterion_value
from .limits import acceleration_limits, check_margin, design_position_bounds
from .rest import RestFourier
from .verify import NOMINAL, DesignCheck, verify_design
from .working_set import feasible, refine
from .world import CollisionScene, World

#: Criterion samples per period and harmonic (module docstring).
COST_SAMPLES = 10
#: Constraint samples per period and harmonic (clearance: four times as many).
CONSTRAINT_SAMPLES = 20
#: Relative std above which a base parameter is called poorly identified.
POOR = 0.1


@dataclass(frozen=True)
class PriorInformation:
    """What earlier data already tell (sequential design).

    Attributes
    ----------
    information : numpy.ndarray
        the inverse covariance of the base parameters, shape (r, r)
    base : numpy.ndarray
        their regressor columns, shape (r,)
    names : list[str]
        the base parameter names, length r
    estimate : numpy.ndarray
        their values (relative std are taken against them), shape (r,)
    noise_std : numpy.ndarray
        per-joint torque noise std [N m or N] of the earlier data, shape (nv,)
    covariance : numpy.ndarray or None
        the covariance of the estimate, shape (r, r): the torque limits then hold for the
        identified model plus ``DesignOptions.sigma`` standard deviations (None: nominal)
    """

    information: np.ndarray
    base: np.ndarray
    names: list[str]
    estimate: np.ndarray
    noise_std: np.ndarray
    covariance: np.ndarray | None = None

    @classmethod
    def from_result(cls, result) -> PriorInformation:
        """From an identification result (its honest covariance and residual variances)."""
        cov = np.asarray(result.covariance, float)
        lam, E = np.linalg.eigh(0.5 * (cov + cov.T))
        inv = np.where(lam > lam.max() * 1e-14, 1.0 / np.where(lam > 0, lam, 1.0), 0.0)
        return cls(
            information=(E * inv) @ E.T,
            base=np.asarray(result.base.independent, int),
            names=list(result.names),
            estimate=np.asarray(result.estimate, float),
            noise_std=np.sqrt(np.asarray(result.noise_variance, float)),
            covariance=0.5 * (cov + cov.T),
        )


@dataclass(frozen=True)
class DesignOptions:
    """Settings of :func:`design_excitation` (sizes in SI units).

    harmonics: Fourier harmonics per joint (>= 2); base_frequency [Hz]: default
    ``1 / duration`` (duration must be a whole number of periods); start: start and end
    pose, joint coordinates [rad or m], shape (nv,) (default: the SRDF's reference
    configuration, else the neutral pose, clipped to the limits); criterion: "d", "cond"
    or "e"; margin: fraction of each limit kept free; acceleration_limit
    [rad/s^2], scalar or (nv,) (default the profile's, else none); torque: impose the
    URDF effort limits (on the nominal model's torques; with a prior that has a covariance,
    on the identified model's plus ``sigma`` standard deviations); sigma: that many
    standard deviations (default 3); clearance [m]: least distance between non-adjacent links and to
    the world; self_collision: check link pairs; noise: torque noise std relative to
    each joint's effort limit (the weights of the criterion; a prior's own noise wins);
    rate [Hz]: sampling of the written trajectory and of the final check; starts,
    refine, maxiter, seed: the search budget.
    """

    harmonics: int = 5
    base_frequency: float | None = None
    start: np.ndarray | None = None
    criterion: str = "d"
    margin: float = 0.05
    acceleration_limit: float | np.ndarray | None = None
    torque: bool = True
    sigma: float = 3.0
    clearance: float = 0.02
    self_collision: bool = True
    noise: float = 0.01
    rate: float = 1000.0
    starts: int = 8
    refine: int = 2
    maxiter: int = 60
    seed: int = 0


@dataclass(frozen=True)
class ExcitationDesign:
    """A designed excitation and what it is predicted to give.

    ``criterion`` is the value minimized (:mod:`.information`); ``criterion_random`` the
    median over the random starts (same limits); ``predicted_std`` the predicted std of
    each base parameter after the run (with the prior, of the combined data) and
    ``prior_std`` before it (None without prior); ``check`` the verification on the
    run's grid (limits used, least clearance and where); ``world`` the obstacles kept clear of;
    ``torque_model`` what the torque limits were checked on ("nominal" or "identified + k sigma").
    """

    trajectory: FourierTrajectory
    duration: float
    rate: float
    criterion_kind: str
    criterion: float
    criterion_random: float
    condition_number: float
    base_names: list[str]
    reference: np.ndarray
    predicted_std: np.ndarray
    prior_std: np.ndarray | None
    check: DesignCheck
    design_time: float
    joint_names: list[str]
    options: DesignOptions = field(repr=False, default_factory=DesignOptions)
    world: World | None = None
    torque_model: str = "nominal"

    @property
    def predicted_relative_std(self) -> np.ndarray:
        """``std / |value|`` per base parameter (NaN where the value is about zero)."""
        return _relative(self.predicted_std, self.reference)

    @property
    def prior_relative_std(self) -> np.ndarray | None:
        """``std / |value|`` per base parameter before the run (None without a prior)."""
        return None if self.prior_std is None else _relative(self.prior_std, self.reference)

    def samples(self, rate: float | None = None):
        """``(t, q, dq, ddq)`` at ``rate`` [Hz] over ``[0, duration]`` (both ends included)."""
        rate = self.rate if rate is None else float(rate)
        n = int(round(self.duration * rate)) + 1
        t = np.linspace(0.0, self.duration, n)
        q, dq, ddq = self.trajectory.sample(t)
        return t, q, dq, ddq

    def torques(self, robot: Robot, rate: float | None = None) -> np.ndarray:
        """Nominal torques ``pinocchio.rnea`` [N m or N] at :meth:`samples`, shape (N, nv)."""
        _, angles, dq, ddq = self.samples(rate)
        q = trajectory_to_configuration(robot, angles)
        model, data = robot.model, robot.model.createData()
        return np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(q.shape[0])])

    def poorly_identified(self, threshold: float = POOR) -> list[tuple[str, float, float | None]]:
        """``(name, predicted relative std, prior relative std)`` of the base parameters whose
        predicted relative std (or prior one) exceeds ``threshold``, worst first."""
        rel = self.predicted_relative_std
        prior = None if self.prior_std is None else _relative(self.prior_std, self.reference)
        rows = []
        for i, name in enumerate(self.base_names):
            before = None if prior is None else float(prior[i])
            worst = max(rel[i], -np.inf if before is None else before)
            if np.isfinite(rel[i]) and worst > threshold:
                rows.append((name, float(rel[i]), before))
        return sorted(rows, key=lambda r: -max(r[1], r[2] or 0.0))

    def summary(self) -> list[str]:
        """The terminal summary: criterion, cond, clearance, limit use, poorly identified."""
        use = self.check.max_usage()
        lines = [
            f"excitation: {self.duration:g} s, {self.trajectory.harmonics} harmonics, "
            f"base frequency {self.trajectory.wf / (2 * math.pi):.4g} Hz, designed in "
            f"{self.design_time:.1f} s",
            f"criterion {self.criterion_kind}: {self.criterion:.4g} (random starts, median: "
            f"{self.criterion_random:.4g}; lower is better); cond {self.condition_number:.4g}",
            (
                f"min clearance {self.check.min_clearance:.4g} m"
                if math.isfinite(self.check.min_clearance)
                else "min clearance: not checked (no collision geometry or pairs)"
            )
            + (
                f" ({' / '.join(self.check.closest_pair)} at t={self.check.closest_time:.3g} s)"
                if self.check.closest_pair
                else ""
            ),  # fmt: skip
            f"max limit use (torques: {self.torque_model}): "
            + ", ".join(
                f"{k} {'-' if v is None else f'{100 * v:.0f} %'}" for k, v in use.items()
            ),  # fmt: skip
        ]
        poor = self.poorly_identified()
        if poor:
            lines.append(f"predicted relative std above {100 * POOR:.0f} % ({len(poor)}):")
            for name, rel, before in poor[:8]:
                was = "" if before is None else f" (before: {_pct(before)})"
                lines.append(f"  {name}: {_pct(rel)}{was}")
        return lines

    def to_dict(self) -> dict:
        rel = self.predicted_relative_std
        out = {
            "duration": self.duration,
            "rate": self.rate,
            "harmonics": self.trajectory.harmonics,
            "base_frequency": self.trajectory.wf / (2 * math.pi),
            "start": self.trajectory.sample(0.0)[0].tolist(),
            "criterion_kind": self.criterion_kind,
            "criterion": self.criterion,
            "criterion_random": self.criterion_random,
            "condition_number": self.condition_number,
            "min_clearance": self.check.min_clearance  # [m]; None: no pair was checked
            if math.isfinite(self.check.min_clearance)
            else None,
            "closest_pair": list(self.check.closest_pair) if self.check.closest_pair else None,
            "closest_time": self.check.closest_time,
            "closest_points": None
            if self.check.closest_points is None
            else self.check.closest_points.tolist(),
            "limit_usage": self.check.usage_dict(self.joint_names),
            "torque_model": self.torque_model,
            "predicted_std": {
                n: float(s) for n, s in zip(self.base_names, self.predicted_std, strict=True)
            },
            "predicted_relative_std": {
                n: (None if not np.isfinite(r) else float(r))
                for n, r in zip(self.base_names, rel, strict=True)
            },
            "design_time": self.design_time,
            "coefficients": {
                "q0": self.trajectory.q0.tolist(),
                "a": self.trajectory.a.tolist(),
                "b": self.trajectory.b.tolist(),
                "wf": self.trajectory.wf,
            },
        }
        if self.prior_std is not None:
            prel = _relative(self.prior_std, self.reference)
            out["prior_relative_std"] = {
                n: (None if not np.isfinite(r) else float(r))
                for n, r in zip(self.base_names, prel, strict=True)
            }
        return out


#: The largest relative torque noise of a design (:class:`DesignOptions` ``noise``).
MAX_DESIGN_NOISE = 100.0


def _pct(x: float) -> str:
    return "not determined" if not np.isfinite(x) else f"{100 * x:.3g} %"


def _relative(std: np.ndarray, ref: np.ndarray) -> np.ndarray:
    scale = np.max(np.abs(ref)) if ref.size else 1.0
    small = np.abs(ref) <= 1e-3 * max(scale, 1e-300)  # products of inertia of ~0: no ratio
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(small, np.nan, std / np.abs(ref))


def design_excitation(
    robot: Robot,
    duration: float,
    *,
    options: DesignOptions | None = None,
    world: World | None = None,
    prior: PriorInformation | None = None,
) -> ExcitationDesign:
    """Design an excitation of ``duration`` [s] (module docstring); returns its design.

    Raises :class:`InputError` for bad settings and :class:`InfeasibleTrajectoryError`
    (naming the joint or pair, the time and the value) when no motion meets them.
    """
    t_begin = time.perf_counter()
    opt = _checked_options(robot, duration, options or DesignOptions())
    duration = float(duration)
    freq = opt.base_frequency or 1.0 / duration
    family = RestFourier(_start_pose(robot, opt), opt.harmonics, 2 * math.pi * freq)
    bounds = _bounds(robot, opt)
    _check_start(robot, family.start, bounds)
    period = 1.0 / freq
    n_cost, n_con = COST_SAMPLES * opt.harmonics, CONSTRAINT_SAMPLES * opt.harmonics
    t_cost = np.arange(n_cost) * (period / n_cost)
    t_con = np.linspace(0.0, period, n_con + 1)
    if prior is None:
        an = analyze(robot, seed=opt.seed)
        base = np.asarray(an.base.independent, int)
        names = list(an.base.base_names)
        theta = robot.nominal_parameters
        reference = theta[base] + an.base.K @ theta[an.base.dependent]
        noise_std = opt.noise * _effort_scale(robot)
        F0 = np.zeros((base.size, base.size))
    else:
        _check_prior(robot, prior)
        base, names, reference = prior.base, prior.names, prior.estimate
        noise_std, F0 = prior.noise_std, prior.information
    info = InformationModel(robot, base, noise_std)
    scale = opt.rate * duration / n_cost  # each grid sample stands for this many samples
    objective = _Objective(info, family, t_cost, F0, scale, opt.criterion)
    scene = _scene(robot, world, opt)
    G, h = linear_constraints(family, t_con, bounds)
    nonlinear: list[TorqueConstraint | ClearanceConstraint] = []
    torque_model = None
    if opt.torque and prior is not None and prior.covariance is not None:
        torque_model = IdentifiedTorques(robot, base, reference, prior.covariance, opt.sigma)
    if opt.torque and np.isfinite(bounds.effort).any():
        if torque_model is None:
            nonlinear.append(TorqueConstraint(robot, family, t_con, bounds.effort))
        else:
            nonlinear.append(
                UncertainTorqueConstraint(robot, family, t_con, bounds.effort, torque_model)
            )
    if scene is not None and scene.n_pairs:
        t_clear = np.linspace(0.0, period, 4 * n_con + 1)
        nonlinear.append(ClearanceConstraint(scene, family, t_clear, opt.clearance))
    best_z, f_random = _search(objective, family.n_free, G, h, t_con.size, nonlinear, opt)
    z, check = _verified(robot, family, best_z, bounds, scene, opt, duration, torque_model)
    f_final = objective.value(z)
    t_pred = np.arange(4 * n_con) * (period / (4 * n_con))  # the prediction: a finer grid
    W = info.matrix(*family.states(z, t_pred))
    F_new = info.information(W, opt.rate * duration / t_pred.size)
    cov = np.linalg.pinv(F0 + F_new)
    lam = np.linalg.eigvalsh(F_new)
    return ExcitationDesign(
        trajectory=family.trajectory(z),
        duration=duration,
        rate=opt.rate,
        criterion_kind=opt.criterion,
        criterion=f_final,
        criterion_random=f_random,
        condition_number=float(math.sqrt(lam[-1] / lam[0])) if lam[0] > 0 else math.inf,
        base_names=names,
        reference=np.asarray(reference, float),
        predicted_std=np.sqrt(np.clip(np.diag(cov), 0.0, None)),
        prior_std=None if prior is None else np.sqrt(np.clip(np.diag(np.linalg.pinv(F0)), 0, None)),
        check=check,
        design_time=time.perf_counter() - t_begin,
        joint_names=list(robot.dof_names),
        options=opt,
        world=world,
        torque_model="nominal" if torque_model is None else f"identified + {opt.sigma:g} sigma",
    )


class _Objective:
    """The criterion of the motion ``z`` and its exact gradient (:mod:`.information`)."""

    def __init__(self, info: InformationModel, family: RestFourier, t, F0, scale, kind):
        self.info, self.family, self.t, self.F0, self.scale, self.kind = (
            info, family, t, F0, scale, kind,
        )  # fmt: skip
        self.bases = family.bases(t)

    def value(self, z) -> float:
        W = self.info.matrix(*self.family.states(z, self.t))
        return criterion_value(self.F0 + self.info.information(W, self.scale), self.kind)[0]

    def value_and_gradient(self, z):
        states = self.family.states(z, self.t)
        W = self.info.matrix(*states)
        f, Gf = criterion_value(self.F0 + self.info.information(W, self.scale), self.kind)
        if not math.isfinite(f):
            return 1e6, np.zeros_like(z)
        g = self.info.pullback(self.info.weights(W, Gf, self.scale), *states)
        P, V, A = self.bases
        grad = P.T @ g[0] + V.T @ g[1] + A.T @ g[2]  # (2L - 2, nv)
        return f, grad.T.ravel()


def _search(objective: _Objective, n_free: int, G, h, n_times: int, nonlinear, opt: DesignOptions):
    """Global start (random feasible starts), then SLSQP from the best ``opt.refine``;
    returns the best feasible ``z`` and the median criterion of the random starts."""
    rng = random_generator(opt.seed)
    starts = []
    for _ in range(opt.starts):
        z = _feasible_start(rng.standard_normal(n_free), G, h, nonlinear)
        if z is not None:
            starts.append((objective.value(z), z))
    if not starts:
        raise InfeasibleTrajectoryError(
            "no random start of the Fourier family fits the limits, torques and clearance "
            "about the start pose: loosen --margin/--clearance or choose another --start"
        )
    starts.sort(key=lambda s: s[0])
    f_random = float(np.median([s[0] for s in starts]))
    best_f, best_z = starts[0]
    for _, z0 in starts[: opt.refine]:
        z, _rows = refine(objective, z0, G, h, n_times, nonlinear, opt.maxiter)
        if z is None:
            continue
        f = objective.value(z)
        if f < best_f and feasible(z, G, h, nonlinear):
            best_f, best_z = f, z
    return best_z, f_random


def _feasible_start(z, G, h, nonlinear, fill: float = 0.9):
    """``z`` scaled about the start pose into the linear limits (``fill`` of the room), then
    halved until the nonlinear constraints hold; None when nothing fits."""
    Gz = G @ z
    with np.errstate(divide="ignore"):
        ratios = np.where(Gz > 0, h / Gz, np.inf)
    if np.any(h < 0):
        return None
    z = z * fill * min(1.0, float(ratios.min())) if np.isfinite(ratios.min()) else z
    for _ in range(12):
        if all(np.all(c(z) >= 0) for c in nonlinear):
            return z
        z = 0.5 * z
    return None


def _verified(robot, family, z, bounds, scene, opt, duration, torque_model=None):
    """Shrink ``z`` about the start pose until the dense check passes (at most 8 steps)."""
    checked = (torque_model or NOMINAL) if opt.torque else None
    for _ in range(8):
        check = verify_design(robot, family.trajectory(z), duration, opt.rate, bounds, scene,
                              clearance=opt.clearance, torque=checked)  # fmt: skip
        if check.violation is None:
            return z, check
        z = 0.9 * z
    raise check.error()


def _scene(robot: Robot, world: World | None, opt: DesignOptions) -> CollisionScene | None:
    """The collision scene; None for a robot without collision geometry and no world."""
    try:
        has_geometry = len(robot.collision_model.geometryObjects) > 0
    except RobotError:
        has_geometry = False
    if not has_geometry:
        if world is not None and world.objects:
            raise InputError(f"robot {robot.name!r} has no collision geometry to check --world")
        return None
    return CollisionScene(robot, world, self_collision=opt.self_collision)


def _checked_options(robot: Robot, duration, opt: DesignOptions) -> DesignOptions:
    if not isinstance(opt, DesignOptions):
        raise InputError(f"options must be DesignOptions, got {type(opt).__name__}")
    if not (isinstance(duration, int | float) and math.isfinite(duration) and duration > 0):
        raise InputError(f"duration must be a positive time [s], got {duration!r}")
    if opt.criterion not in CRITERIA:
        raise InputError(f"criterion must be one of {', '.join(CRITERIA)}, got {opt.criterion!r}")
    if not 2 <= int(opt.harmonics) <= 50 or int(opt.harmonics) != opt.harmonics:
        raise InputError(f"harmonics must be an integer in [2, 50], got {opt.harmonics}")
    check_margin(opt.margin)
    for name in ("clearance", "noise", "rate", "sigma"):
        v = getattr(opt, name)
        if not (math.isfinite(v) and (v > 0 or (name in ("clearance", "sigma") and v == 0))):
            raise InputError(f"{name} must be a positive number, got {v}")
    if opt.noise > MAX_DESIGN_NOISE:
        raise InputError(
            f"noise is the torque noise std relative to the effort limits: at most "
            f"{MAX_DESIGN_NOISE:g}, got {opt.noise:g}"
        )
    check_count(duration * opt.rate, MAX_STEPS, "the design's sample count (duration x rate)")
    for name, least in (("starts", 1), ("refine", 0), ("maxiter", 0), ("seed", 0)):
        v = getattr(opt, name)
        if int(v) != v or v < least:
            raise InputError(f"{name} must be an integer >= {least}, got {v}")
    if opt.base_frequency is not None:
        f = float(opt.base_frequency)
        periods = duration * f
        if (
            not (math.isfinite(f) and f > 0)
            or abs(periods - round(periods)) > 1e-6
            or round(periods) < 1
        ):
            raise InputError(
                f"duration {duration} s must be a whole number of periods of the base "
                f"frequency; got base_frequency={opt.base_frequency} Hz ({periods:.4g} periods)"
            )
    if 1.0 / (opt.base_frequency or 1.0 / duration) * opt.rate < 4 * opt.harmonics:
        raise InputError(f"rate {opt.rate} Hz is too low for {opt.harmonics} harmonics")
    acc: Any = opt.acceleration_limit
    if acc is None and robot.profile is not None and robot.profile.excitation is not None:
        acc = robot.profile.excitation.acceleration_limit
        if isinstance(acc, tuple) and len(acc) not in (1, robot.nv):
            prof = robot.profile
            raise InputError(
                f"profile {prof.source or prof.name}: excitation.acceleration_limit holds "
                f"{len(acc)} values (one per joint of the profile's joints), but this robot "
                f"moves {robot.nv}: give acceleration_limit (--acceleration-limit) for them"
            )
    return replace(opt, acceleration_limit=acc)


def _bounds(robot: Robot, opt: DesignOptions) -> Bounds:
    m = opt.margin
    lo, hi = design_position_bounds(robot)
    width = hi - lo
    vel = (1.0 - m) * robot.velocity_bounds()
    acc = (1.0 - m) * acceleration_limits(robot, opt.acceleration_limit)
    eff = robot.effort_limit.astype(float)
    eff = np.where((eff > 0) & (eff < 1e6), (1.0 - m) * eff, np.nan)
    return Bounds(lo + m * width, hi - m * width, vel, acc, eff)


def _effort_scale(robot: Robot) -> np.ndarray:
    eff = robot.effort_limit.astype(float)
    ok = (eff > 0) & (eff < 1e6)
    return np.where(ok, eff, np.median(eff[ok]) if ok.any() else 1.0)


def _start_pose(robot: Robot, opt: DesignOptions) -> np.ndarray:
    idx, cont = dof_layout(robot)
    if opt.start is not None:
        start = np.asarray(opt.start, float)
        if start.shape != (robot.nv,) or not np.all(np.isfinite(start)):
            raise InputError(f"start must be {robot.nv} finite joint positions, got {start.shape}")
        return start
    refs = robot.model.referenceConfigurations
    names = [k for k in ("default", "home", "ready", "qref") if k in refs]
    q = np.asarray(refs[names[0]], float) if names else robot.neutral()
    start = q[idx].copy()
    start[cont] = np.arctan2(q[idx[cont] + 1], q[idx[cont]])
    lo, hi = design_position_bounds(robot)
    width = hi - lo
    return np.clip(start, lo + (opt.margin + 0.01) * width, hi - (opt.margin + 0.01) * width)


def _check_start(robot: Robot, start: np.ndarray, bounds: Bounds) -> None:
    bad = np.flatnonzero((start < bounds.lo) | (start > bounds.hi))
    if bad.size:
        j = int(bad[0])
        raise InputError(
            f"start pose of joint {robot.dof_names[j]!r} is {start[j]:.4g}, outside its range "
            f"[{bounds.lo[j]:.4g}, {bounds.hi[j]:.4g}] with the margin"
        )


def _check_prior(robot: Robot, prior: PriorInformation) -> None:
    r = prior.base.size
    if prior.information.shape != (r, r) or len(prior.names) != r or prior.estimate.shape != (r,):
        raise InputError(f"prior: expected information ({r}, {r}), {r} names and estimates")
    if prior.base.max(initial=-1) >= robot.n_parameters or prior.noise_std.shape != (robot.nv,):
        raise InputError(
            f"the result's base columns and joints do not fit {robot.name!r} with these joint "
            f"terms ({robot.n_parameters} parameters, {robot.nv} joints): give the same "
            "--friction/--armature/--joints as for identify"
        )
