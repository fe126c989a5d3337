"""manip_id: dynamic parameter identification of robot manipulators.

The linear-in-parameters model is the centre of everything::

    tau = Y(q, dq, ddq) theta                          inverse dynamics
    M(q) v + C(q, dq) w + g(q) = Y(q, dq, v, w) theta  Slotine-Li form
    z(t) = phi(t)^T theta                              scalar regression

Pinocchio supplies the rigid-body regressor; manip_id adds joint-level terms,
rank analysis, estimators, adaptive control, data handling and pictures.
Data flow one way: robot + data -> regressor -> (identifiability) ->
estimator -> result -> report / figures / meshcat.

Every public name is imported on first use (PEP 562): ``import manip_id`` loads
no submodule, ``from manip_id import identify`` loads :mod:`manip_id.identification`
and what it needs. To export a new name, add it to its submodule's tuple in
``_EXPORTS`` below (or, for a name that differs from the submodule's, to
``_ALIASES``); ``__all__`` follows.
"""

from __future__ import annotations

from typing import Any

from ._lazy import LazyExports, by_module

__version__ = "0.1.0"

#: Public name -> the submodule (relative to this package) that defines it.
#: Add new exports here; nothing else in this file needs editing.
_EXPORTS: dict[str, tuple[str, ...]] = {
    ".control.adaptive": (
        "AdaptiveGains",
        "CompositeLaw",
        "SlotineLiController",
        "default_gains",
        "lyapunov_function",
    ),
    ".control.closed_loop": ("ClosedLoopOptions", "ClosedLoopRun", "compare_fixed", "with_payload"),
    ".datasets": ("Dataset", "FileSpec", "check_robot", "load_dataset", "save_dataset"),
    ".errors": (
        "DataError",
        "InfeasibleTrajectoryError",
        "InputError",
        "ManipIdError",
        "RankDeficiencyError",
        "RobotError",
    ),
    ".physics.consistency": ("PhysicalConsistencyError", "check_consistency", "pseudo_inertia"),
    ".export": ("export_mjcf", "export_payload_urdf", "export_urdf"),
    ".estimators": (
        "ConcurrentLearningEstimator",
        "DREMEstimator",
        "GradientEstimator",
        "InformationAccumulator",
        "LeastSquaresSolution",
        "RLSEstimator",
        "solve_accumulator",
        "solve_stacked",
    ),
    ".identifiability": (
        "BaseParameters",
        "RankAnalysis",
        "analyze",
        "analyze_dataset",
        "analyze_information",
        "analyze_trajectory",
    ),
    ".identification": (
        "ConsistentOptions",
        "FileOptions",
        "IdentificationResult",
        "ModelOptions",
        "OnlineOptions",
        "PreprocessOptions",
        "RunOptions",
        "UncertaintyOptions",
        "accumulate_file",
        "build_problem",
        "identify",
        "load_result",
        "solve",
    ),
    ".models": ("accumulate_energy", "accumulate_momentum", "check_energy_base"),
    ".payload": (
        "DriveGainResult",
        "PayloadResult",
        "identify_drive_gains",
        "identify_payload",
        "load_torque_scale",
    ),
    ".robot.regressor": (
        "iter_regressor",
        "iter_slotine_li_regressor",
        "joint_torques",
        "regressor",
        "slotine_li_regressor",
    ),
    ".robot.model": ("JointTerms", "Robot", "available_robots", "load_robot"),
    ".signals": ("Lowpass", "preprocess"),
    ".physics.perturbation": ("perturb_parameters",),
    ".simulation": ("MeasurementNoise", "SimulatedData", "simulate"),
    ".trajectories": (
        "DesignOptions",
        "ExcitationDesign",
        "FourierTrajectory",
        "check_limits",
        "design_excitation",
        "random_trajectory",
    ),
}

#: Public name -> (submodule, attribute) for names exported under another name.
_ALIASES: dict[str, tuple[str, str | None]] = {
    "simulate_adaptive": (".control.closed_loop", "simulate"),
}

_LAZY = LazyExports(__name__, {**by_module(_EXPORTS), **_ALIASES})
__all__ = _LAZY.names


def __getattr__(name: str) -> Any:
    """Import the submodule that defines ``name`` on first access (PEP 562)."""
    return _LAZY.load(name, globals())


def __dir__() -> list[str]:
    return _LAZY.listing(globals())
