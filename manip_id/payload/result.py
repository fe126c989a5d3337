"""The results of payload and drive-gain identification, and how a payload estimate is built.

:class:`PayloadEstimate` is the payload in its frame (mass, centre of mass, inertia
about the CoM, each with its standard deviation by the delta method, or ``None``
and named when the data do not fix it); :class:`PayloadResult` and
:class:`DriveGainResult` add the fit. Both results share one JSON block
(:func:`fit_dict`) and one text header (:func:`fit_header`).
"""

from __future__ import annotations

import math
import os
import sys
import warnings
from dataclasses import dataclass, field
from types import FrameType

import numpy as np

from ..errors import PayloadWarning
from ..identifiability import RankAnalysis
from ..metrics import finite_or_none
from ..physics.consistency import EIG_TOLERANCE
from .geometry import (
    DEPENDS,
    INERTIA_COMPONENTS,
    PAYLOAD_NAMES,
    QUANTITY_NAMES,
    QUANTITY_UNITS,
    PayloadFrame,
    payload_quantities,
    pseudo_inertia_eigenvalues,
)

#: Files of this package: a warning points at the first frame outside them.
_PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__)) + os.sep


# ====================================================================== results
def fit_dict(r) -> dict:
    """The JSON of what a payload and a drive-gain result share: the payload, the sample
    counts, the errors, the rows left out, the base parameters, solver, warnings, timings."""
    return {
        "payload": r.payload.to_dict(),
        "n_samples": dict(r.n_samples),
        "relative_error": {k: finite_or_none(v) for k, v in r.relative_error.items()},
        "relative_error_per_joint": {
            k: [finite_or_none(x) for x in v] for k, v in r.relative_error_per_joint.items()
        },
        "rows_left_out": dict(zip(r.dof_names, (int(x) for x in r.rows_left_out), strict=True)),
        "sigma2": finite_or_none(r.sigma2),
        "condition_number": finite_or_none(r.condition_number),
        "base_parameters": [
            {"name": n, "expression": e, "value": finite_or_none(x), "std": finite_or_none(s)}
            for n, e, x, s in zip(
                r.base_names, r.base_expressions, r.base_estimate, r.base_std, strict=True
            )
        ],
        "solver": r.solver,
        "warnings": list(r.warnings),
        "timings": {k: round(float(v), 6) for k, v in r.timings.items()},
    }


def samples_text(n_samples: dict) -> str:
    """``"N unloaded + M loaded samples"``: the sample counts of a result, as its header shows."""
    return f"{n_samples['unloaded']} unloaded + {n_samples['loaded']} loaded samples"


@dataclass(frozen=True)
class PayloadEstimate:
    """An identified (or partly given) payload, in its frame, with its uncertainty.

    Attributes
    ----------
    frame
        frame name; parent_joint: the joint carrying it
    standard
        ``phi`` (10,): m [kg], h = m c [kg m], inertia about the frame origin
        [kg m^2]; the representative with zero unidentifiable components
    standard_std
        standard deviations of ``phi`` (10,) (NaN where not identifiable)
    values
        ``[m, c (3), I_c (6)]`` [kg, m, kg m^2] (inertia about the CoM, frame axes)
    std
        their standard deviations (delta method), shape (10,); NaN where not identifiable
    identifiable
        per quantity of :data:`QUANTITY_NAMES`, whether the data fix it
    standard_identifiable
        per standard parameter, whether the data fix it
    known
        per quantity, whether it was given (drive gains with a known payload)
    combinations
        the payload base parameters the data fix, in standard names
    unidentifiable
        the directions of ``phi`` no data can see
    min_eigenvalue
        smallest eigenvalue of the pseudo-inertia ``J(phi)`` (NumPy eigvalsh)
        of :attr:`standard`
    physically_consistent
        ``min_eigenvalue > 1e-10 max|eig J|``; ``None`` when some
        directions of ``phi`` are not identifiable and no consistent fit chose them
    """

    frame: str
    parent_joint: str
    standard: np.ndarray
    standard_std: np.ndarray
    values: np.ndarray
    std: np.ndarray
    identifiable: np.ndarray
    standard_identifiable: np.ndarray
    known: np.ndarray
    combinations: list[str]
    unidentifiable: list[str]
    min_eigenvalue: float
    physically_consistent: bool | None

    @property
    def mass(self) -> float:
        """Mass [kg]."""
        return float(self.values[0])

    @property
    def com(self) -> np.ndarray:
        """Centre of mass in the frame [m], shape (3,)."""
        return self.values[1:4].copy()

    @property
    def inertia(self) -> np.ndarray:
        """Inertia about the CoM (Ixx, Ixy, Iyy, Ixz, Iyz, Izz) [kg m^2], shape (6,)."""
        return self.values[4:].copy()

    @property
    def point_mass(self) -> bool:
        """A positive mass whose inertia about its centre of mass is zero within 3 std
        (every moment identified): a point mass, whose pseudo-inertia is singular, so that
        noise alone makes its smallest eigenvalue slightly negative or positive."""
        ok = self.identifiable[4:] | self.known[4:]
        if not (self.mass > 0 and ok.all()):
            return False
        sd = np.where(self.known[4:], 0.0, np.asarray(self.std[4:], dtype=float))
        return bool(np.all(np.abs(self.inertia) <= 3.0 * sd + 1e-12 * self.mass))

    def _shown(self, i: int, arr: np.ndarray):
        return finite_or_none(arr[i]) if (self.identifiable[i] or self.known[i]) else None

    def to_dict(self) -> dict:
        """The JSON ``payload`` block; what the data do not identify is ``None``."""
        v = [self._shown(i, self.values) for i in range(10)]
        s = [
            finite_or_none(self.std[i]) if self.identifiable[i] and not self.known[i] else None
            for i in range(10)
        ]
        return {
            "frame": self.frame,
            "parent_joint": self.parent_joint,
            "mass": v[0],
            "mass_std": s[0],
            "com": v[1:4],
            "com_std": s[1:4],
            "inertia": v[4:],
            "inertia_std": s[4:],
            "inertia_components": list(INERTIA_COMPONENTS),
            "units": {"mass": "kg", "com": "m", "inertia": "kg m^2 (about the CoM, frame axes)"},
            "identifiable": [
                n for n, ok in zip(QUANTITY_NAMES, self.identifiable, strict=True) if ok
            ],
            "not_identifiable": [
                n
                for n, ok, kn in zip(QUANTITY_NAMES, self.identifiable, self.known, strict=True)
                if not ok and not kn
            ],
            "known": [n for n, kn in zip(QUANTITY_NAMES, self.known, strict=True) if kn],
            "identifiable_combinations": list(self.combinations),
            "unidentifiable_directions": list(self.unidentifiable),
            "standard_parameters": [
                {
                    "name": n,
                    "value": finite_or_none(x) if ok else None,
                    "std": finite_or_none(sd) if ok else None,
                    "identifiable": bool(ok),
                }
                for n, x, sd, ok in zip(
                    PAYLOAD_NAMES,
                    self.standard,
                    self.standard_std,
                    self.standard_identifiable,
                    strict=True,
                )
            ],
            "physically_consistent": (
                None if self.physically_consistent is None else bool(self.physically_consistent)
            ),
            "pseudo_inertia_min_eigenvalue": finite_or_none(self.min_eigenvalue),
            "point_mass": self.point_mass,
        }

    def table(self) -> str:
        """One line per quantity: value, standard deviation, or why it is missing."""
        lines = [f"payload at {self.frame} (parent joint {self.parent_joint}):"]
        for i, (n, u) in enumerate(zip(QUANTITY_NAMES, QUANTITY_UNITS, strict=True)):
            if self.known[i]:
                lines.append(f"  {n:<12} {self.values[i]:13.6g} {u:<7} (given)")
            elif self.identifiable[i]:
                lines.append(f"  {n:<12} {self.values[i]:13.6g} {u:<7} +- {self.std[i]:.3g}")
            else:
                lines.append(f"  {n:<12} {'-':>13} {u:<7} not identifiable from these torques")
        if self.physically_consistent is None:
            lines.append(
                "  physically consistent: not decided (unidentifiable directions are free; "
                "a consistent fit chooses them)"
            )
        elif self.point_mass and not self.physically_consistent:
            lines.append(
                "  a point mass: its inertia about the centre of mass is zero within 3 std "
                f"(smallest pseudo-inertia eigenvalue {self.min_eigenvalue:.3g}, noise about "
                "a singular one); physical as a point mass"
            )
        else:
            state = "yes" if self.physically_consistent else "NO"
            lines.append(
                f"  physically consistent: {state} (smallest pseudo-inertia eigenvalue "
                f"{self.min_eigenvalue:.3g})"
            )
        return "\n".join(lines)


@dataclass(frozen=True)
class PayloadResult:
    """Payload identification: the payload, the robot's base parameters, the fit.

    Attributes
    ----------
    robot_name, method ("ols" or "wls"), payload (:class:`PayloadEstimate`)
    base_names, base_expressions
        the robot's base parameters
    base_estimate, base_std
        their estimate (or the known one) and standard deviations (r,)
    known_base
        whether the base parameters came from an earlier identification
    consistent
        whether the payload was constrained to be physically consistent
    sigma2
        residual variance [(N m)^2]; condition_number: of the joint regressor
    n_samples
        {"unloaded": N_u, "loaded": N_l}
    relative_error
        {"unloaded": e_u, "loaded": e_l} (``||tau - tau_hat|| / ||tau||``)
    relative_error_per_joint
        the same per joint, (nv,) each
    rows_left_out
        per joint, rows dropped by the velocity deadband
    payload_test
        the Wald statistic that the loaded runs show a payload, its degrees
        of freedom and p-value
    solver
        how it was solved; warnings: what the user should know; timings [s]
    runs
        {"unloaded": [...], "loaded": [...]}, per run what its source reported
        (:attr:`RunSums.runs`: a file's data quality and preprocessing, read where the
        run was accumulated; None for arrays)
    """

    robot_name: str
    method: str
    payload: PayloadEstimate
    base_names: list[str]
    base_expressions: list[str]
    base_estimate: np.ndarray
    base_std: np.ndarray
    known_base: bool
    consistent: bool
    sigma2: float
    condition_number: float
    n_samples: dict
    relative_error: dict
    relative_error_per_joint: dict
    rows_left_out: np.ndarray
    payload_test: dict
    solver: str
    dof_names: list[str]
    warnings: list[str] = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    runs: dict = field(default_factory=dict)
    #: how the covariance was estimated: ``{method, bandwidth, inflation, n_blocks, ...}``
    #: (``hac``: autocorrelation-consistent from the runs' per-block sums)
    uncertainty: dict | None = None

    def to_dict(self) -> dict:
        """JSON-ready: ``payload`` and the fit (lists, floats, None)."""
        return {
            "command": "payload",
            "uncertainty": self.uncertainty,
            "robot": self.robot_name,
            "joints": list(self.dof_names),
            "method": self.method,
            "consistent": self.consistent,
            "known_base": self.known_base,
            **fit_dict(self),
            "payload_test": {
                k: finite_or_none(v) if k != "dof" else int(v) for k, v in self.payload_test.items()
            },
        }

    def table(self) -> str:
        """A readable summary."""
        re = self.relative_error
        lines = [
            f"payload identification of {self.robot_name} ({self.method.upper()}"
            + (", consistent" if self.consistent else "")
            + (", known base" if self.known_base else "")
            + f"): {samples_text(self.n_samples)}",
            self.payload.table(),
            "relative torque error: "
            + ", ".join(f"{k} {100 * v:.3f} %" for k, v in re.items() if v is not None),
            f"solver: {self.solver}",
        ]
        return "\n".join(lines)


@dataclass(frozen=True)
class DriveGainResult:
    """Drive gains ``tau_j = g_j i_j`` [N m / A per joint], with the base and payload parameters.

    Attributes
    ----------
    robot_name, method ("ols" or "tls"), dof_names
    gains, gains_std
        shape (nv,) [N m / A] (NaN where not determined); ``gains_std`` holds for
        correlated residuals (:mod:`manip_id.payload.gain_uncertainty`)
    gains_std_white
        the white-noise standard deviations, shape (nv,) [N m / A]
    uncertainty
        how ``gains_std`` was estimated: ``{method, bandwidth, inflation, n_blocks, ...}``
    determined
        per joint, whether the data fix its gain
    payload
        :class:`PayloadEstimate` (``known`` marks the given quantities)
    base_names, base_expressions, base_estimate, base_std
        the robot's base parameters
        [in torque units]
    sigma2
        residual variance, [A^2] for "ml" (current units), [(N m)^2] otherwise;
        condition_number: of the homogeneous system with the known columns moved right
    n_samples, relative_error, relative_error_per_joint
        as :class:`PayloadResult`, the
        error relative to the torques ``g_j i_j``
    rows_left_out
        per joint, rows dropped by the velocity deadband
    solver, warnings, timings, runs (as :class:`PayloadResult`)
    """

    robot_name: str
    method: str
    dof_names: list[str]
    gains: np.ndarray
    gains_std: np.ndarray
    determined: np.ndarray
    payload: PayloadEstimate
    base_names: list[str]
    base_expressions: list[str]
    base_estimate: np.ndarray
    base_std: np.ndarray
    sigma2: float
    condition_number: float
    n_samples: dict
    relative_error: dict
    relative_error_per_joint: dict
    rows_left_out: np.ndarray
    solver: str
    warnings: list[str] = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    runs: dict = field(default_factory=dict)
    gains_std_white: np.ndarray | None = None
    uncertainty: dict | None = None

    def gain_rows(self) -> list[dict]:
        """Per joint: ``joint``, ``gain``, ``std``, ``std_percent`` (``100 std / |gain|``)
        and ``determined``; ``None`` where the data do not fix the gain."""
        rows = []
        for j, name in enumerate(self.dof_names):
            ok = bool(self.determined[j])
            g = finite_or_none(self.gains[j]) if ok else None
            s = finite_or_none(self.gains_std[j]) if ok else None
            sw = None
            if ok and self.gains_std_white is not None:
                sw = finite_or_none(self.gains_std_white[j])
            pct = None
            if ok and g not in (None, 0.0) and s is not None:
                pct = 100.0 * s / abs(g)
            rows.append(
                {
                    "joint": name,
                    "gain": g,
                    "std": s,
                    "std_white": sw,
                    "std_percent": pct,
                    "determined": ok,
                }
            )
        return rows

    def to_dict(self) -> dict:
        """JSON-ready: ``drive_gains`` (one per joint, in joint order) and ``torque_scale``."""
        gains = self.gain_rows()
        return {
            "command": "drive-gains",
            "robot": self.robot_name,
            "joints": list(self.dof_names),
            "method": self.method,
            "drive_gains": gains,
            "torque_scale": [g["gain"] for g in gains],
            "units": "N m / A (N / A for prismatic joints): torque = gain * current",
            "uncertainty": self.uncertainty,
            **fit_dict(self),
        }

    def table(self) -> str:
        """A readable summary: one line per joint gain, then the payload."""
        lines = [
            f"drive gains of {self.robot_name} ({self.method.upper()}): "
            + samples_text(self.n_samples)
        ]
        w = max(len(n) for n in self.dof_names)
        for j, (name, row) in enumerate(zip(self.dof_names, self.gain_rows(), strict=True)):
            if self.determined[j]:
                pct = row["std_percent"]
                if pct is None:  # a zero gain, or a std that is not finite
                    pct = math.nan if self.gains[j] else math.inf
                lines.append(
                    f"  {name:<{w}}  {self.gains[j]:12.6g} +- {self.gains_std[j]:.3g}  "
                    f"({pct:.3g} %)"
                )
            else:
                lines.append(f"  {name:<{w}}  {'-':>12}  not determined by these data")
        lines.append(self.payload.table())
        lines.append(f"solver: {self.solver}")
        return "\n".join(lines)


# ====================================================================== building an estimate
def estimate_from_base(
    pf: PayloadFrame,
    ra: RankAnalysis,
    cols: np.ndarray,
    psi: np.ndarray,
    cov_psi: np.ndarray,
    *,
    phi_known: np.ndarray | None = None,
    known_cols: np.ndarray | None = None,
    phi_override: np.ndarray | None = None,
) -> PayloadEstimate:
    """Assemble the payload from its base estimate ``psi`` over the payload ``cols``."""
    ind = cols[ra.base.independent]  # indices into phi (10,)
    R = np.zeros((10, ind.size))
    R[ind, np.arange(ind.size)] = 1.0
    phi = R @ psi
    if phi_known is not None:
        phi = phi + phi_known
    if phi_override is not None:
        phi = phi_override
    cov_phi = R @ cov_psi @ R.T
    null = np.zeros((10, ra.null_space.shape[1]))
    null[cols] = ra.null_space
    scale = np.linalg.norm(null, axis=0)
    null = null / np.where(scale > 0, scale, 1.0)
    std_ident = np.ones(10, dtype=bool)
    if null.size:
        std_ident = np.abs(null).max(axis=1) < 1e-9
    known_std = np.zeros(10, dtype=bool)
    if known_cols is not None:
        known_std[np.asarray(known_cols, dtype=np.intp)] = True
    std_ident = std_ident & ~known_std
    fixed = std_ident | known_std
    ident = np.array([all(fixed[k] for k in dep) for dep in DEPENDS])
    known_q = np.array([all(known_std[k] for k in dep) for dep in DEPENDS])
    ident = ident & ~known_q
    phi_std = np.sqrt(np.maximum(np.diag(cov_phi), 0.0))
    phi_std = np.where(std_ident, phi_std, np.nan)
    if phi[0] != 0.0:
        values, G = payload_quantities(phi)
        std = np.sqrt(np.maximum(np.einsum("ik,kl,il->i", G, cov_phi, G), 0.0))
    else:
        values, std = np.full(10, np.nan), np.full(10, np.nan)
        values[0] = 0.0
    std = np.where(ident, std, np.nan)
    lam = pseudo_inertia_eigenvalues(phi)
    consistent: bool | None = bool(lam[0] > EIG_TOLERANCE * np.abs(lam).max())
    if not fixed.all() and phi_override is None:
        consistent = None  # the free directions decide: only the constrained fit says
    return PayloadEstimate(
        frame=pf.name,
        parent_joint=pf.joint_name,
        standard=phi,
        standard_std=phi_std,
        values=values,
        std=std,
        identifiable=ident,
        standard_identifiable=std_ident,
        known=known_q,
        combinations=list(ra.base.expressions),
        unidentifiable=list(ra.unidentifiable),
        min_eigenvalue=float(lam[0]),
        physically_consistent=consistent,
    )


def known_estimate(pf: PayloadFrame, phi: np.ndarray, ra: RankAnalysis) -> PayloadEstimate:
    """A fully given payload (every parameter known)."""
    values, _ = payload_quantities(phi)
    lam = pseudo_inertia_eigenvalues(phi)
    return PayloadEstimate(
        frame=pf.name,
        parent_joint=pf.joint_name,
        standard=phi,
        standard_std=np.full(10, np.nan),
        values=values,
        std=np.full(10, np.nan),
        identifiable=np.zeros(10, dtype=bool),
        standard_identifiable=np.zeros(10, dtype=bool),
        known=np.ones(10, dtype=bool),
        combinations=[],
        unidentifiable=list(ra.unidentifiable),
        min_eigenvalue=float(lam[0]),
        physically_consistent=bool(lam[0] > EIG_TOLERANCE * np.abs(lam).max()),
    )


def record_warning(messages: list[str], text: str) -> None:
    """Record ``text`` in ``messages`` (the result's ``warnings``) and warn with it
    (:class:`~manip_id.errors.PayloadWarning`), pointing at the first caller outside this
    package (the user's call, from whichever step of it warns)."""
    messages.append(text)
    frame: FrameType | None = sys._getframe(0)
    level = 1
    while frame is not None and frame.f_code.co_filename.startswith(_PACKAGE_DIR):
        frame, level = frame.f_back, level + 1
    warnings.warn(text, PayloadWarning, stacklevel=level)
