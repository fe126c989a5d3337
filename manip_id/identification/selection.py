"""Friction model selection per joint, and the shapes of the nonlinear laws by variable
projection.

Candidates (:data:`CANDIDATES`; every one with the offset ``fo`` when
``SelectionOptions.offset``, the torque sensor's bias), in the laws of
:mod:`manip_id.robot.friction`::

    linear       fv dq + fc sign(dq)
    asymmetric   fvp, fvn, and fcp, fcn (fc with the offset)
    stribeck     fv dq + (fc + fs' exp(-(dq/vs)^2)) sign(dq)        vs per joint
    sigmoid      fv dq + fsg (S(a (dq + c)) - S(a c))                a, c per joint
    position     fv dq + fc sign(dq) + sum_k hks sin(k q) + hkc cos(k q)
    load         fv dq + fc sign(dq) + fl |tau_load| sign(dq)      (nominal tau_load)
    temperature  (fv + fvt (T - T0)) dq + (fc + fct (T - T0)) sign(dq)
                 only when the data carry a temperature (:func:`select_model_files`)
    hysteresis   fv dq + fc sign(dq) + fh s, s the Dahl state        xc per joint
    X+position   a joint's best of asymmetric / stribeck / sigmoid, plus the harmonics

Each fit is the usual one (``fit(robot) -> IdentificationResult``: the same accumulated
sums, streamed, forked or on Dask, whichever path ``fit`` takes), with one candidate on
every joint at once: a joint's friction columns appear only in its own torque row, so
each joint is scored on its own row by the information criterion of the training data

    BIC_j = n ln(sigma_j^2) + k_j ln(n)           (training sums: sigma_j^2 the joint's
                                                   residual variance, k_j its base
                                                   joint-term parameters, n samples)

The choice never looks at validation data: a validation error of the model chosen on
that same validation file would no longer be independent (it was, before: chosen and
reported on one file). When the fits carry validation data, each candidate's validation
error is shown beside its BIC, for information only. The shapes (Stribeck ``vs``,
sigmoid slope ``a``, hysteresis length ``xc``) are chosen by variable projection: the
linear coefficients are solved for every value of a grid (one fit per value), each
joint keeps its best value, then the best is refined by a bisection in log(shape) (two
fits per round, each joint its own value); the sigmoid's shift ``c`` is then chosen
among :data:`SIGMOID_SHIFTS` and 0. The chosen per-joint models make one
:class:`~manip_id.robot.model.JointTerms` with ``per_dof`` (the terms each joint keeps) and
``shapes``; :func:`select_model` fits it last, and its result carries
``context["friction_selection"]``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import InputError, RankDeficiencyError
from ..metrics import finite_or_none
from ..robot.friction import FrictionShapes
from ..robot.model import JointTerms, Robot
from .result import IdentificationResult
from .temperature import candidate_reference

#: How every choice is made (the JSON's ``friction_criterion``).
CRITERION = "BIC on the training data"
#: The candidate models, in the order they are tried.
CANDIDATES: tuple[str, ...] = (
    "linear",
    "asymmetric",
    "stribeck",
    "sigmoid",
    "position",
    "load",
    "temperature",
    "hysteresis",
)
#: The candidates tried by default: all but ``temperature``, which needs a measured
#: temperature (:func:`select_model_files` adds it when every file has one).
DEFAULT_CANDIDATES: tuple[str, ...] = tuple(c for c in CANDIDATES if c != "temperature")
_KINDS = {
    "linear": ("viscous", "coulomb"),
    "asymmetric": ("asymmetric",),
    "stribeck": ("viscous", "coulomb", "stribeck"),
    "sigmoid": ("viscous", "sigmoid"),
    "position": ("viscous", "coulomb", "position"),
    "load": ("viscous", "coulomb", "load"),
    "temperature": ("viscous", "coulomb", "temperature"),
    "hysteresis": ("viscous", "coulomb", "hysteresis"),
}
#: Default grids: Stribeck velocities vs [rad/s], sigmoid slopes a [s/rad].
STRIBECK_GRID = (0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5)
SIGMOID_GRID = (5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0)
#: Sigmoid shifts c [rad/s] tried at the chosen slopes (besides 0).
SIGMOID_SHIFTS = (-0.04, -0.02, -0.01, 0.01, 0.02, 0.04)
#: Default grid of hysteresis (Dahl) lengths xc [rad].
HYSTERESIS_GRID = (0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05)
#: The searched laws: their shape field of :class:`FrictionShapes` and its name in the table.
_SHAPE_FIELDS = {
    "stribeck": ("stribeck_velocity", "vs"),
    "sigmoid": ("sigmoid_slope", "slope"),
    "hysteresis": ("hysteresis_length", "xc"),
}


@dataclass(frozen=True)
class SelectionOptions:
    """What :func:`select_model` tries.

    Attributes
    ----------
    candidates : tuple of str
        Models to try, some of :data:`CANDIDATES` (default :data:`DEFAULT_CANDIDATES`).
    offset : bool
        Every candidate carries the offset ``fo``.
    harmonics : int
        Order K of the ``position`` candidate.
    stribeck_grid : tuple of float
        Stribeck velocities vs to try [rad/s], ascending.
    sigmoid_grid : tuple of float
        Sigmoid slopes a to try [s/rad], ascending.
    refine : int
        Rounds of refinement of the grid's best shape (a bisection in log(shape):
        half the grid step, then a quarter, ...; two fits per round).
    sigmoid_shifts : tuple of float
        Sigmoid shifts c [rad/s] tried at the chosen slopes, besides 0 (Gaz's phi3).
    combine : bool
        Also try, per joint, its best nonlinear law plus the ``position`` harmonics
        (one more fit; candidates ``"<law>+position"``).
    hysteresis_grid : tuple of float
        Hysteresis (Dahl) lengths xc to try [rad], ascending.
    """

    candidates: tuple[str, ...] = DEFAULT_CANDIDATES
    offset: bool = True
    harmonics: int = 2
    stribeck_grid: tuple[float, ...] = STRIBECK_GRID
    sigmoid_grid: tuple[float, ...] = SIGMOID_GRID
    refine: int = 3
    sigmoid_shifts: tuple[float, ...] = SIGMOID_SHIFTS
    combine: bool = True
    hysteresis_grid: tuple[float, ...] = HYSTERESIS_GRID

    def __post_init__(self):
        if int(self.refine) < 0:
            raise InputError(f"refine must be a number of rounds >= 0, got {self.refine}")
        bad = [c for c in self.candidates if c not in CANDIDATES]
        if bad or not self.candidates:
            raise InputError(f"candidates must be some of {list(CANDIDATES)}, got {bad or '[]'}")
        for name in ("stribeck_grid", "sigmoid_grid", "hysteresis_grid"):
            g = getattr(self, name)
            if not g or any(not (math.isfinite(x) and x > 0) for x in g) or list(g) != sorted(g):
                raise InputError(f"{name} must be positive values in ascending order, got {g}")


@dataclass
class Candidate:
    """One candidate model of one joint: its fitted shape and scores."""

    model: str
    parameters: dict
    validation_error: float | None
    bic: float
    n_parameters: int | None = None  # the joint's identified coefficients plus its shapes

    def to_dict(self) -> dict:
        """JSON-ready (``n_parameters``: the joint's base coefficients plus its shapes)."""
        return {
            "model": self.model,
            "parameters": self.parameters,
            "n_parameters": self.n_parameters,
            "validation_error": finite_or_none(self.validation_error),
            "bic": finite_or_none(self.bic),
        }


@dataclass
class JointSelection:
    """The candidates of one joint and the chosen one."""

    joint: str
    chosen: str
    candidates: list[Candidate] = field(default_factory=list)

    def to_dict(self) -> dict:
        """JSON-ready: ``joint``, ``chosen``, ``candidates``."""
        return {
            "joint": self.joint,
            "chosen": self.chosen,
            "candidates": [c.to_dict() for c in self.candidates],
        }


@dataclass
class FrictionSelection:
    """The outcome of :func:`select_model`.

    Attributes
    ----------
    joints : list of JointSelection
        Per joint its candidates and the chosen model.
    criterion : str
        how the choice was made: :data:`CRITERION` (the training data's BIC).
    terms : JointTerms
        The chosen per-joint model (``per_dof`` and ``shapes``).
    n_fits : int
        Fits run (grid points and refinements included).
    """

    joints: list[JointSelection]
    criterion: str
    terms: JointTerms
    n_fits: int

    def to_dict(self) -> list[dict]:
        """The JSON ``friction_selection``: per joint ``joint``, ``chosen``, ``candidates``."""
        return [j.to_dict() for j in self.joints]

    def text(self) -> str:
        """One line per joint: the chosen model and the candidates' scores."""
        lines = [f"friction model per joint (by {self.criterion}):"]
        for j in self.joints:
            cells = []
            for c in j.candidates:
                if not math.isfinite(c.bic):
                    score = "n/a (not excited)"
                else:
                    score = f"BIC {c.bic:.1f}"
                    if c.validation_error is not None:  # shown, not used
                        score += f", validation {100 * c.validation_error:.3f} %"
                cells.append(f"{c.model} {score}")
            lines.append(f"  {j.joint}: {j.chosen} ({', '.join(cells)})")
        return "\n".join(lines)


# ------------------------------------------------------------------- terms
def candidate_terms(
    base: JointTerms, model: str, opts: SelectionOptions, shapes: FrictionShapes | None = None
) -> JointTerms:
    """The joint terms of one candidate on every joint (``base``'s armature and spring, and
    its temperature reference ``T0``)."""
    kinds = set(_KINDS[model]) | ({"offset"} if opts.offset else set())
    shapes = _with_reference(shapes, base)
    return JointTerms(
        armature=base.armature,
        spring=base.spring,
        viscous="viscous" in kinds,
        coulomb="coulomb" in kinds,
        offset="offset" in kinds,
        asymmetric="asymmetric" in kinds,
        stribeck="stribeck" in kinds,
        sigmoid="sigmoid" in kinds,
        harmonics=opts.harmonics if "position" in kinds else 0,
        load="load" in kinds,
        temperature="temperature" in kinds,
        hysteresis="hysteresis" in kinds,
        shapes=shapes,
    )


def _with_reference(shapes: FrictionShapes | None, base: JointTerms) -> FrictionShapes | None:
    """``shapes`` with the temperature reference ``T0`` of ``base``'s shapes, if any."""
    t0 = None if base.shapes is None else base.shapes.temperature_reference
    return shapes if t0 is None else replace(shapes or FrictionShapes(), temperature_reference=t0)


def combined_terms(base: JointTerms, per_joint: list[JointTerms], shapes) -> JointTerms:
    """One :class:`JointTerms` holding each joint's own model (``per_dof``)."""
    flags = {
        k: any(getattr(t, k) for t in per_joint)
        for k in (
            "viscous", "coulomb", "offset", "asymmetric", "stribeck", "sigmoid", "load",
            "temperature", "hysteresis",
        )
    }  # fmt: skip
    return JointTerms(
        armature=base.armature,
        spring=base.spring,
        harmonics=max(t.harmonics for t in per_joint),
        shapes=_with_reference(shapes, base),
        per_dof=tuple(t.enabled for t in per_joint),
        **flags,
    )


# ----------------------------------------------------------------- scoring
def joint_coefficients(robot: Robot, result: IdentificationResult) -> np.ndarray:
    """Per joint the base parameters of one fit that are its own joint terms, shape (nv,)."""
    k = np.zeros(robot.nv)
    for c in result.base.independent:
        owner = robot.layout.owner(int(c))
        if owner.kind == "joint":
            k[owner.index] += 1
    return k


def joint_scores(
    robot: Robot, result: IdentificationResult
) -> tuple[np.ndarray | None, np.ndarray]:
    """Per joint ``(validation_error, bic)`` of one fit (module docstring), shapes (nv,)."""
    n = max(int(result.n_samples), 1)
    k = joint_coefficients(robot, result)
    var = np.maximum(np.asarray(result.noise_variance, dtype=float), 1e-300)
    bic = n * np.log(var) + k * math.log(n)
    v = result.relative_error.validation_per_joint
    return (None if v is None else np.asarray(v, dtype=float)), bic


def _score(val, bic):
    """The score a choice uses: the training BIC (never the validation error)."""
    return bic


@dataclass
class _Trial:
    """One fit with one candidate on every joint (shapes per joint)."""

    shape: np.ndarray | None  # per joint, the shape value of this trial
    val: np.ndarray | None
    bic: np.ndarray
    shift: np.ndarray | None = None  # per joint, the sigmoid shift c [rad/s]
    k: np.ndarray | None = None  # per joint, its base coefficients in this fit


# ------------------------------------------------------------------ search
def _shape_field(model: str) -> str:
    return _SHAPE_FIELDS[model][0]


def _fit_trial(fit, robot, model, opts, shape: np.ndarray | None, shift=None) -> _Trial:
    """One fit; a joint whose law column these data do not excite (a Stribeck velocity
    below every velocity it reached) drops it and scores inf for this trial; a law that
    leaves other directions unexcited (too many harmonics for a joint's range) scores inf
    on every joint (the linear candidate must fit)."""
    shapes = None
    if shape is not None:
        shapes = FrictionShapes(**{_shape_field(model): tuple(map(float, shape))})
    if shift is not None:
        shapes = replace(shapes or FrictionShapes(), sigmoid_shift=tuple(map(float, shift)))
    terms = candidate_terms(robot.terms, model, opts, shapes)
    dropped: set[int] = set()
    for _ in range(3):
        r = robot.with_terms(terms)
        try:
            res = fit(r)
            val, bic = joint_scores(r, res)
            break
        except RankDeficiencyError as exc:
            lost = _unexcited_terms(r, exc.directions)
            if lost is None and model == "linear":
                raise
            if lost is None:  # the law over-fits these data as a whole: not a candidate
                return _Trial(shape, np.full(robot.nv, np.inf), np.full(robot.nv, np.inf), shift)
            keep = [list(terms.enabled) for _ in range(robot.nv)]
            for j, t in lost:
                dropped.add(j)
                keep[j].remove(t)
            terms = replace(terms, per_dof=tuple(tuple(k) for k in keep))
    else:  # pragma: no cover - three rounds drop every law column
        raise InputError(f"the {model} candidate is not excited by these data")
    for j in dropped:
        bic[j] = np.inf
        if val is not None:
            val[j] = np.inf
    return _Trial(shape, val, bic, shift, joint_coefficients(r, res))


def _unexcited_terms(robot: Robot, directions) -> list[tuple[int, str]] | None:
    """``(dof, term)`` of directions that are one friction-law column alone, else None."""
    out = []
    for d in directions:
        dof, _, term = str(d).rpartition(".")
        lone = term in ("fs", "fsg", "fvp", "fvn", "fcp", "fcn", "fh")  # a law's own columns
        if dof not in robot.dof_names or not lone:
            return None
        out.append((robot.dof_names.index(dof), term))
    return out or None


def _best(trials: list[_Trial]) -> list[int]:
    """Per joint the index of its best trial."""
    scores = np.array([_score(t.val, t.bic) for t in trials])  # (n_trials, nv)
    return list(np.nanargmin(np.where(np.isfinite(scores), scores, np.inf), axis=0))


def _search(fit, robot: Robot, model: str, opts: SelectionOptions) -> tuple[_Trial, int]:
    """The per-joint best shape of a nonlinear law: the grid, then ``opts.refine`` rounds
    of a bisection in log(shape) around each joint's best (two fits per round)."""
    nv = robot.nv
    grid = {
        "stribeck": opts.stribeck_grid,
        "sigmoid": opts.sigmoid_grid,
        "hysteresis": opts.hysteresis_grid,
    }[model]
    trials = [_fit_trial(fit, robot, model, opts, np.full(nv, g)) for g in grid]
    winner = _winners(trials)
    n = len(trials)
    h = math.log(grid[-1] / grid[0]) / max(len(grid) - 1, 1)  # grid step in log(shape)
    for _ in range(opts.refine if len(grid) > 1 else 0):
        h /= 2
        for sign in (-1.0, 1.0):
            shape = np.asarray(winner.shape, dtype=float) * math.exp(sign * h)
            trial = _fit_trial(fit, robot, model, opts, shape)
            winner = _winners([winner, trial])
            n += 1
    if model == "sigmoid" and opts.sigmoid_shifts:  # Gaz's phi3, at the chosen slopes
        winner.shift = np.zeros(nv)
        for c in opts.sigmoid_shifts:
            trial = _fit_trial(fit, robot, model, opts, winner.shape, np.full(nv, c))
            winner = _winners([winner, trial])
            n += 1
    return winner, n


def _winners(trials: list[_Trial]) -> _Trial:
    """The per-joint winners of some trials as one trial (each joint its own shape)."""
    pick = [trials[b] for b in _best(trials)]
    shape = np.array([t.shape[j] for j, t in enumerate(pick)])  # type: ignore[index]
    val = None
    if pick[0].val is not None:
        val = np.array([t.val[j] for j, t in enumerate(pick)])  # type: ignore[index]
    bic = np.array([t.bic[j] for j, t in enumerate(pick)])
    shift = None
    if any(t.shift is not None for t in pick):
        shift = np.array([0.0 if t.shift is None else t.shift[j] for j, t in enumerate(pick)])
    k = None
    if all(t.k is not None for t in pick):  # each joint's coefficients in its winning fit
        k = np.array([t.k[j] for j, t in enumerate(pick)])  # type: ignore[index]
    return _Trial(shape, val, bic, shift, k)


def select_model(
    fit: Callable[[Robot], IdentificationResult],
    robot: Robot,
    options: SelectionOptions | None = None,
) -> tuple[IdentificationResult, FrictionSelection]:
    """Choose each joint's friction model (module docstring) and fit the chosen model.

    Parameters
    ----------
    fit : callable
        ``fit(robot) -> IdentificationResult``: the identification of the caller's data
        (with validation data when the choice should use them) for a robot's joint terms.
    robot : Robot
        The robot; its armature and spring are kept, its friction terms replaced.
    options : SelectionOptions or None
        The candidates and grids (None: the defaults).

    Returns
    -------
    (result, selection)
        The chosen model's result (``context["friction_selection"]`` holds the table)
        and the :class:`FrictionSelection`.
    """
    opts = options or SelectionOptions()
    trials: dict[str, _Trial] = {}
    n_fits = 0
    for model in opts.candidates:
        if model in _SHAPE_FIELDS:
            trials[model], n = _search(fit, robot, model, opts)
        else:
            trials[model], n = _fit_trial(fit, robot, model, opts, None), 1
        n_fits += n
    shapes = _shapes(trials)
    joints = [
        JointSelection(name, "", [_candidate(m, t, j) for m, t in trials.items()])
        for j, name in enumerate(robot.dof_names)
    ]
    if opts.combine and "position" in trials and len(trials) > 1:
        n_fits += _combine(fit, robot, opts, joints, shapes)
    per_joint = []
    for js in joints:
        js.chosen = _choose(js.candidates)
        per_joint.append(_model_terms(robot.terms, js.chosen, opts, shapes))
    terms = combined_terms(robot.terms, per_joint, shapes)
    result = fit(robot.with_terms(terms))
    selection = FrictionSelection(joints, CRITERION, terms, n_fits + 1)
    ctx = {
        **result.context,
        "friction_selection": selection.to_dict(),
        "friction_criterion": selection.criterion,
        "joint_terms_per_joint": {
            name: list(keep)
            for name, keep in zip(robot.dof_names, terms.per_dof or (), strict=True)
        },
    }
    if terms.shapes is not None:
        ctx["friction_shapes"] = terms.shapes.to_dict()
    return replace(result, context=ctx), selection


def _choose(candidates: list[Candidate]) -> str:
    """The chosen model: the least training BIC (the first such, simpler ones first)."""
    bic = np.array([c.bic for c in candidates], dtype=float)
    return candidates[int(np.nanargmin(np.where(np.isfinite(bic), bic, np.inf)))].model


def _candidate(model: str, trial: _Trial, j: int, name: str | None = None) -> Candidate:
    params = {}
    if trial.shape is not None:
        params = {_SHAPE_FIELDS[model][1]: float(trial.shape[j])}
    if trial.shift is not None:
        params["shift"] = float(trial.shift[j])
    val = None if trial.val is None else float(trial.val[j])
    k = None if trial.k is None else int(trial.k[j]) + len(params)
    return Candidate(name or model, params, val, float(trial.bic[j]), k)


def _model_terms(base: JointTerms, name: str, opts: SelectionOptions, shapes) -> JointTerms:
    """The terms of a candidate name, ``"stribeck"`` or a combination ``"stribeck+position"``."""
    law, _, extra = name.partition("+")
    terms = candidate_terms(base, law, opts, shapes)
    return replace(terms, harmonics=opts.harmonics) if extra == "position" else terms


def _combine(fit, robot, opts, joints: list[JointSelection], shapes) -> int:
    """Each joint's best law other than ``linear``/``position`` plus the harmonics, in one
    fit (each joint its own law); adds the candidates ``"<law>+position"``. Returns 1."""
    names = []
    for js in joints:
        laws = [c for c in js.candidates if c.model not in ("linear", "position")]
        if not laws:
            return 0
        best = min(laws, key=lambda c: float(c.bic))
        names.append(best)
    per_joint = [_model_terms(robot.terms, c.model + "+position", opts, shapes) for c in names]
    r = robot.with_terms(combined_terms(robot.terms, per_joint, shapes))
    try:
        res = fit(r)
        val, bic = joint_scores(r, res)
    except RankDeficiencyError:  # the combination over-fits these data: not a candidate
        return 1
    k = joint_coefficients(r, res)
    for j, (js, c) in enumerate(zip(joints, names, strict=True)):
        v = None if val is None else float(val[j])
        n = int(k[j]) + len(c.parameters)
        js.candidates.append(Candidate(c.model + "+position", c.parameters, v, float(bic[j]), n))
    return 1


def select_model_files(
    robot: Robot,
    fit: Callable[[Robot], IdentificationResult],
    specs: list,
    vspecs: list | None,
    scans: dict,
    *,
    selection: SelectionOptions | None = None,
) -> tuple[Robot, FrictionSelection]:
    """:func:`select_model` on log files: ``fit(robot)`` is the files' least-squares
    identification with the candidate's joint terms (give it validation files for the
    validation error). The ``temperature`` candidate joins the default ones (``selection``
    None or the defaults) when every
    file (``specs``, ``vspecs``; ``scans`` holds their scans) carries a temperature (the
    reference ``T0`` from the training ones); otherwise the candidates are the defaults.
    Returns the robot with the chosen per-joint model and the selection."""
    default = selection is None or selection == SelectionOptions()
    with_t0 = candidate_reference(robot, specs, vspecs, scans) if default else None
    if with_t0 is not None:  # every file has a temperature: the temperature law joins
        robot, selection = with_t0, SelectionOptions(candidates=CANDIDATES)
    _, chosen = select_model(fit, robot, selection)
    return robot.with_terms(chosen.terms), chosen


def _shapes(trials: dict[str, _Trial]) -> FrictionShapes | None:
    """The per-joint best shapes of the nonlinear laws tried (None: neither was)."""
    vs, slope, xc = trials.get("stribeck"), trials.get("sigmoid"), trials.get("hysteresis")
    if vs is None and slope is None and xc is None:
        return None
    return FrictionShapes(
        hysteresis_length=None if xc is None else tuple(map(float, xc.shape)),  # type: ignore[arg-type]
        stribeck_velocity=None if vs is None else tuple(map(float, vs.shape)),  # type: ignore[arg-type]
        sigmoid_slope=None if slope is None else tuple(map(float, slope.shape)),  # type: ignore[arg-type]
        sigmoid_shift=None
        if slope is None or slope.shift is None
        else tuple(map(float, slope.shift)),
    )


__all__ = [
    "CANDIDATES",
    "CRITERION",
    "DEFAULT_CANDIDATES",
    "Candidate",
    "FrictionSelection",
    "JointSelection",
    "SelectionOptions",
    "candidate_terms",
    "combined_terms",
    "joint_scores",
    "select_model",
    "select_model_files",
]
