"""``manip-id identify``: base parameters of a robot from a log or a simulation.

Pipeline: load (``--data``: NPZ, CSV, ROS 2 bags or a Panda log folder) or simulate
(``--simulate``), split off validation data (``--split`` or ``--validate``),
preprocess each part alone (resampling, zero-phase low-pass, ddq by central
differences, edge trimming: :func:`manip_id.signals.preprocess`), identify the
base parameters, print a table and optionally write JSON, a report and a URDF.

This module declares the options; :mod:`._identify` checks them and picks the run path:
log files (:mod:`._files`), many files on Dask (:mod:`._fleet`), a simulation
(:mod:`._simulated`), or the acceleration-free models (:mod:`._acceleration_free`).
Those load Pinocchio: they are imported when the command runs (:func:`._common.command`),
so that ``manip-id --help`` stays light.
"""

from __future__ import annotations

import argparse

from ..signals import DEFAULT_CUTOFF, DEFAULT_ORDER
from ._common import (
    SIM_DEFAULTS,
    add_execution_arguments,
    add_file_arguments,
    add_quiet_verbose,
    add_robot_arguments,
    add_scheduler_argument,
    add_stream_arguments,
    command,
    cutoff_value,
)

METHODS = ("ols", "wls", "rls", "gradient", "iv", "didim")


def register(sub) -> None:
    p = sub.add_parser(
        "identify",
        help="identify base parameters from data or a simulation",
        description="Identify the base dynamic parameters of ROBOT from measured data (--data) or "
        "from a simulated excitation (--simulate); print the parameters with their "
        "relative standard deviations, the condition number and the relative torque "
        "errors on training and validation data.",
    )
    add_robot_arguments(p)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--data",
        metavar="FILE",
        nargs="+",
        action="extend",
        help="one or more measurement files (--data a b, or --data a --data b; each read in "
        "chunks and preprocessed on its own): .npz (t, q, dq, tau[, ddq, temp, joint_names]), .csv "
        "(t,q_<joint>...,dq_<joint>...,tau_<joint>...), a ROS 2 bag (rosbag2 folder or "
        ".mcap) or a Panda log folder; FILE@START:STOP [s] or FILE@#A:#B [rows] for a window",
    )
    p.add_argument(
        "--column",
        action="append",
        default=[],
        metavar="FIELD=COLUMNS",
        help="CSV column map for other layouts (repeatable): FIELD is t, q, dq, ddq, tau, temp "
        "(the temperature of --friction temperature: one column per joint or one for all) or "
        "joint_names; COLUMNS a header name, a glob such as 'pos*', or a comma-separated list of "
        "names or 0-based indices, e.g. --column t=stamp --column q='pos*'",
    )
    src.add_argument(
        "--simulate",
        action="store_true",
        help="simulate measurements along a random Fourier excitation",
    )
    sim = p.add_argument_group("simulation (with --simulate)")
    sim.add_argument(
        "--duration",
        type=float,
        default=None,
        help=f"seconds [default {SIM_DEFAULTS['duration']:g}]",
    )
    sim.add_argument(
        "--rate",
        type=float,
        default=None,
        help=f"sampling rate [Hz] of the simulation [default {SIM_DEFAULTS['rate']:g}]; with "
        "--data, the rate of files without a time column (t_k = k / HZ)",
    )
    sim.add_argument(
        "--noise",
        type=float,
        default=None,
        help="torque noise, relative to each joint's RMS torque "
        f"[default {SIM_DEFAULTS['noise']:g}]",
    )
    sim.add_argument(
        "--seed",
        type=int,
        default=None,
        help=f"seed of trajectory and noise [default {SIM_DEFAULTS['seed']}]",
    )
    sim.add_argument(
        "--optimize",
        action="store_true",
        help="design the excitation (D-optimal, rest to rest, within the limits, torques and "
        "self-collision: as manip-id excite) instead of a random one",
    )
    p.add_argument(
        "--method",
        choices=METHODS,
        default="wls",
        help="estimator [default wls]; iv (IDIM-IV) and didim (DIDIM) are the closed-loop "
        "estimators of logs recorded with the known controller of --controller",
    )
    p.add_argument(
        "--controller",
        metavar="FILE.toml",
        default=None,
        help="the PD/PID controller of closed-loop logs (kp, kd[, ki] per joint; the "
        "reference columns qref, dqref of the logs): needed by --method iv and didim",
    )
    p.add_argument(
        "--uncertainty",
        choices=("auto", "white", "hac"),
        default="auto",
        help="covariance of the estimate: hac holds for correlated residuals (per-block "
        "scores, Bartlett kernel, automatic bandwidth), white is sigma^2 (Y^T Y)^-1; auto "
        "[default]: hac when the data give enough blocks, else white",
    )
    p.add_argument(
        "--model",
        choices=("dynamic", "energy", "momentum"),
        default="dynamic",
        help="dynamic: tau = Y(q, dq, ddq) theta [default]; energy (over intervals) or "
        "momentum (filtered): no acceleration, only q and dq filtered (one --data file)",
    )
    p.add_argument(
        "--window-length",
        type=float,
        default=None,
        metavar="SECONDS",
        help="energy interval / momentum row spacing [s] (default 0.2; momentum filter "
        "bandwidth 3 / SECONDS rad/s)",
    )
    val = p.add_mutually_exclusive_group()
    val.add_argument(
        "--validate",
        metavar="FILE",
        nargs="+",
        action="extend",
        help="one or more validation files (same formats and windows as --data)",
    )
    val.add_argument(
        "--split",
        type=float,
        metavar="FRACTION",
        help="identify on the first FRACTION of the samples, validate on the rest",
    )
    p.add_argument(
        "--refine",
        choices=("output-error",),
        default=None,
        help="refine the estimate by output error: Levenberg-Marquardt on the model rolled "
        "out from the measured torques over short windows (docs/cli.md)",
    )
    p.add_argument(
        "--refine-horizon",
        type=float,
        metavar="SECONDS",
        default=None,
        help="window length of --refine [s] [default 0.1]",
    )
    p.add_argument(
        "--refine-windows",
        type=int,
        metavar="N",
        default=None,
        help="number of windows of --refine [default: 20000 steps' worth, at least 4 per "
        "base parameter, at most what the data hold]",
    )
    p.add_argument(
        "--rollout",
        type=float,
        metavar="SECONDS",
        default=None,
        help="roll the identified and the nominal model forward on the validation data over "
        "SECONDS (as manip-id validate): JSON 'rollout', and a figure in --report",
    )
    sig = p.add_argument_group(
        "signal processing (for data without ddq, or when --cutoff is given)"
    )
    sig.add_argument(
        "--cutoff",
        type=cutoff_value,
        default=None,
        help=f"low-pass cut-off [Hz], or auto: 3 x the frequency below which 99 %% of each "
        f"file's velocity power lies (printed with its reason) [default {DEFAULT_CUTOFF:g}]",
    )
    sig.add_argument(
        "--order",
        type=int,
        default=DEFAULT_ORDER,
        help=f"Butterworth order [default {DEFAULT_ORDER}]",
    )
    sig.add_argument(
        "--trim",
        type=float,
        default=None,
        help="seconds dropped at each end of each part [default: the filter's edge transient]",
    )
    sig.add_argument("--decimate", type=int, default=1, help="keep every D-th sample [default 1]")
    p.add_argument("--json", metavar="OUT", help="write the results as JSON to OUT")
    p.add_argument(
        "--report",
        metavar="DIR",
        help="write a report folder: result.json, torque fit, residuals, singular values, "
        "trajectory vs limits (--simulate), the robot scene (scene.html) and index.html",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace a non-empty --report folder or an existing --export-urdf file",
    )
    add_quiet_verbose(
        p,
        "also print every base parameter (value, std, nominal, unit, flags), the audit's "
        "table and each file's data quality [default: the answer in about 25 lines; the full "
        "table is always in --json and --report]",
    )
    rep = p.add_argument_group("report and flags")
    rep.add_argument(
        "--scene-assets",
        choices=("inline", "external"),
        default="inline",
        help="inline: scene.html stands alone; external: the viewer script and the scene data "
        "are written once beside it (meshcat.min.js, scene-data.js) [default inline]",
    )
    rep.add_argument(
        "--poorly-identified",
        type=float,
        default=None,
        metavar="PERCENT",
        help="flag a base parameter 'poorly identified' above this std [%%] [default 10]",
    )
    rep.add_argument(
        "--condition-limit",
        type=float,
        default=None,
        metavar="C",
        help="warn when the condition number exceeds C [default 100]",
    )
    add_execution_arguments(p)
    phys = p.add_argument_group("physically consistent estimation (ols, wls)")
    phys.add_argument(
        "--consistent",
        action="store_true",
        help="estimate standard parameters that describe a real robot: every body's "
        "pseudo-inertia positive definite, armature and viscous/Coulomb friction >= 0, the "
        "same least-squares fit through the base parameters",
    )
    phys.add_argument(
        "--solver",
        default="sdp",
        metavar="{sdp,logchol}",
        help="sdp: semidefinite program (cvxpy + Clarabel); logchol: log-Cholesky "
        "Levenberg-Marquardt [default sdp]",
    )
    phys.add_argument(
        "--prior",
        default="nominal",
        metavar="{nominal,none}",
        help="what fills the directions the data cannot identify: the URDF's parameters "
        "(log-det divergence) or none (feasibility alone) [default nominal]",
    )
    phys.add_argument(
        "--prior-weight",
        type=float,
        default=None,
        help="weight of the prior against the fit measured in standard deviations, the OLS "
        "ones inflated by the feasibility fit's chi-square over its expected value when the "
        "residuals are not white [default 0.1]",
    )
    phys.add_argument(
        "--bounds",
        default="geometry",
        choices=("geometry", "none"),
        help="geometry: each body's mass inside a bounding ellipsoid of its link (collision "
        "or visual geometry, else its kinematic segment); none: consistency alone "
        "[default geometry]",
    )
    phys.add_argument(
        "--mass-range",
        metavar="LO,HI",
        help="each body's mass within LO..HI times its nominal mass, e.g. 0.33,3 "
        "[default: no range]",
    )
    phys.add_argument(
        "--total-mass",
        metavar="KG[+-TOL]",
        help="the moving bodies' total mass [kg], within +-TOL [default: free; TOL 5 %%]",
    )
    phys.add_argument(
        "--export-urdf",
        metavar="OUT.urdf",
        help="write the robot's URDF with the identified inertias and friction (needs "
        "--consistent); armature and offset go to OUT.identified.json next to it",
    )
    phys.add_argument(
        "--export-mjcf",
        metavar="OUT.xml",
        help="write the identified robot as MuJoCo MJCF: inertias, armature, damping, "
        "frictionloss, meshes (needs --consistent); sidecar OUT.xml.identified.json",
    )
    add_file_arguments(p)
    _add_fleet_arguments(p)
    add_stream_arguments(p, rate=False)  # --rate: the simulation's, above
    p.set_defaults(func=command("manip_id.cli._identify"))


# ------------------------------------------------------------------- options
def _add_fleet_arguments(parser: argparse.ArgumentParser) -> None:
    """The fleet options of ``manip-id identify``."""
    g = parser.add_argument_group("many files (Dask)")
    add_scheduler_argument(
        g, "each file is one task, the sums are added on the cluster and solved here (ols, wls)"
    )
    g.add_argument(
        "--per-file",
        action="store_true",
        help="also each file's own estimate and errors (JSON per_file, report figure)",
    )
    g.add_argument(
        "--block",
        type=int,
        default=None,
        metavar="SAMPLES",
        help="with --scheduler or --per-file: cut longer files into tasks of SAMPLES samples",
    )
