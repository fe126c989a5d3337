"""Options and helpers shared by the subcommands.

Robot options and loading, output reservation, progress bars, CSV column maps, the
data-file options of identify (specs, preprocessing options), the consistency options,
the URDF export and the end of a run (publish the outputs, say where they are).

Nothing here loads Pinocchio: ``manip-id --help`` builds every parser from this module.
What the commands share once they run is in :mod:`._runtime`; a command's run function
is imported by :func:`command` when the command runs.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import math
import os
import sys
import warnings

from .._io import OutputSet, write_json  # noqa: F401 (the commands import write_json here)
from ..datasets import parse_file_spec
from ..datasets.layout import FIELDS
from ..errors import InputError, shorten
from ..robot.profiles import find_profile, load_profile
from ..robot.transmission import Transmission, load_transmission
from ..signals import DEFAULT_CUTOFF, preprocess
from ..signals.bandwidth import choose_cutoff


def add_robot_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ROBOT and the joint-term options ``--friction``, ``--armature``, ``--spring``."""
    parser.add_argument(
        "robot",
        metavar="ROBOT",
        help="example-robot-data name (see 'manip-id robots'), a .urdf path, or 'msd'",
    )
    parser.add_argument(
        "--friction",
        default=None,
        help="comma-separated friction laws per joint: viscous, coulomb, offset, asymmetric, "
        "stribeck, sigmoid, position[:K], load, temperature (needs a temp field: --column "
        "temp=...), hysteresis (docs/friction.md); 'auto' (identify --data): "
        "chosen per joint by the training data's BIC (never the validation data) "
        "[default: the robot profile's (robots/ROBOT.toml), else none]",
    )
    parser.add_argument(
        "--armature",
        action="store_true",
        default=None,
        help="model a rotor inertia (armature) per joint [default: the robot profile's, else off]",
    )
    parser.add_argument(
        "--spring",
        action="store_true",
        default=None,
        help="model a linear spring per joint [default: the robot profile's, else off]",
    )
    parser.add_argument(
        "--joints",
        default=None,
        help="comma-separated active joints, the others locked [default: the robot profile's, "
        "else every joint]",
    )
    parser.add_argument(
        "--profile",
        default=None,
        help="identification profile: a robot name or a .toml file, 'none' for none "
        "[default robots/ROBOT.toml when ROBOT is a name]; options given here override it",
    )
    parser.add_argument(
        "--package-dir",
        action="append",
        default=[],
        help="folder where package:// paths of a URDF resolve (repeatable)",
    )


def workers_value(text: str) -> int | str:
    """``--workers``: ``auto`` or a positive number of processes (argparse type)."""
    value = str(text).strip().lower()
    if value == "auto":
        return "auto"
    if value.isdigit() and int(value) >= 1:
        return int(value)
    raise argparse.ArgumentTypeError(f"expected 'auto' or a positive integer, got {text!r}")


#: ``manip_id.robot.compiled_regressor.MODES`` and its environment variable, spelled here so that
#: ``--help`` does not load Pinocchio (tests/test_workers_auto.py checks that they agree).
REGRESSOR_MODES = ("auto", "compiled", "pinocchio")
REGRESSOR_ENV = "MANIP_ID_REGRESSOR"


class RegressorMode(argparse.Action):
    """``--regressor MODE``: sets the regressor mode of this process and of the workers it
    starts (``MANIP_ID_REGRESSOR``, read by :mod:`manip_id.robot.compiled_regressor`)."""

    def __call__(self, parser, namespace, values, option_string=None):
        os.environ[REGRESSOR_ENV] = str(values)
        setattr(namespace, self.dest, values)


def add_execution_arguments(parser: argparse.ArgumentParser, *, workers: bool = True) -> None:
    """Add how the work runs: ``--chunk``, ``--workers`` (when ``workers``), ``--regressor``."""
    parser.add_argument(
        "--chunk", type=int, default=1024, help="samples per regressor chunk [default 1024]"
    )
    if workers:
        parser.add_argument(
            "--workers",
            type=workers_value,
            default="auto",
            help="processes accumulating parts of the data (ols, wls): a number, or 'auto' "
            "[default auto: every core this process may use for large inputs, from "
            "manip_id.execution.FORK_MIN_SAMPLES samples on, else 1]",
        )
    parser.add_argument(
        "--regressor",
        choices=REGRESSOR_MODES,
        action=RegressorMode,
        default=None,
        help="rigid-body regressor: 'compiled' (numba, a block of samples per call), "
        "'pinocchio' (one computeJointTorqueRegressor call per sample, the reference) or "
        "'auto' (compiled for large inputs when numba is installed) [default: "
        "$MANIP_ID_REGRESSOR, else auto]",
    )


def explicit_workers(args: argparse.Namespace) -> int:
    """``--workers`` as a number of processes; ``auto`` counts as 1 (it never forks for
    work that must run in order or in one process) [-]."""
    workers = getattr(args, "workers", 1)
    return 1 if workers == "auto" else int(workers)


def profile_option(args: argparse.Namespace):
    """``--profile``: a name or path, False for ``none``, None when not given."""
    value = getattr(args, "profile", None)
    return False if value == "none" else value


def profile_from_args(args: argparse.Namespace):
    """The :class:`~manip_id.robot.profiles.RobotProfile` the options select (robot not loaded).

    ``--profile`` when given (``none``: no profile), else ``robots/ROBOT.toml`` for a
    robot given by name; None when there is none.
    """
    value = profile_option(args)
    if value is False:
        return None
    if value is not None:
        return load_profile(value)
    return find_profile(str(getattr(args, "robot", "") or ""))


#: Options naming input files or folders (the outputs must not be one of them).
INPUT_OPTIONS = ("robot", "data", "validate", "urdf", "package_dir")
#: Options naming other files a command reads (results, references, designs, worlds,
#: transmissions, profiles, calibration and payload runs): never to be written over.
READ_OPTIONS = (
    "model", "reference", "thresholds", "trajectory", "world", "previous", "transmission",
    "profile", "calibrate", "unloaded", "loaded", "torque_scale_from", "known_base", "input",
)  # fmt: skip
#: Options naming output files, and the option naming a report folder.
FILE_OUTPUT_OPTIONS = ("json", "html", "export_urdf")


def input_paths(args: argparse.Namespace) -> list[str]:
    """Every existing path among the input options of ``args`` (``FILE@WINDOW``: FILE)."""
    paths = []
    for name in INPUT_OPTIONS + READ_OPTIONS:
        value = getattr(args, name, None)
        for item in value if isinstance(value, list) else [value]:
            if not isinstance(item, str) or not item:
                continue
            if not os.path.exists(item) and "@" in item:  # a window of a file
                item = item.rsplit("@", 1)[0]
            if os.path.exists(item):
                paths.append(item)
    return paths


def reserve_outputs(args: argparse.Namespace):
    """Check and reserve every output option of ``args`` before the work; returns the set.

    ``--json``, ``--html``, ``--export-urdf`` (files) and ``--report`` (a folder, claimed
    atomically, replaced with ``--force`` only when manip-id wrote it) are checked
    against each other and against the inputs (:mod:`manip_id._io`). The command writes
    them with ``outputs.write_json(...)`` / ``claim.write(...)`` and publishes them all
    with ``outputs.publish()`` at the end. Also checks ``--seed`` and caps ``--workers``.
    """
    check_seed_and_workers(args)
    outputs = getattr(args, "outputs", None)
    if outputs is None:
        outputs = args.outputs = OutputSet()
    outputs.add_inputs(input_paths(args))
    args.report_claim = None
    if getattr(args, "report", None) is not None:  # first: a file inside it then collides
        args.report_claim = outputs.report(args.report, "--report", force=args.force)
    for name in FILE_OUTPUT_OPTIONS:
        value = getattr(args, name, None)
        if value is not None:
            outputs.file(value, "--" + name.replace("_", "-"))
    return outputs


def check_seed_and_workers(args: argparse.Namespace) -> None:
    """A negative ``--seed`` is an error; ``--workers`` above the core count is capped."""
    seed = getattr(args, "seed", None)
    if seed is not None and not 0 <= seed < 2**63:
        raise InputError(f"--seed must be an integer in [0, 2**63), got {seed}")
    workers = getattr(args, "workers", None)
    if workers is not None and workers != "auto":
        if workers < 1:
            raise InputError(f"--workers must be >= 1, got {workers}")
        affinity = getattr(os, "sched_getaffinity", None)  # the cores this process may use
        cores = len(affinity(0)) if affinity is not None else (os.cpu_count() or 1)
        if workers > cores:
            warn(f"--workers {workers} capped at the {cores} cores of this machine")
            args.workers = cores


def warn(message: str) -> None:
    """``manip-id: warning: message`` on stderr, once (the CLI's warning printer)."""
    warnings.warn(message, UserWarning, stacklevel=2)


# ------------------------------------------------------------------ progress
#: A progress bar appears on stderr (a terminal, without --quiet) once a run passes this [s].
PROGRESS_DELAY = 2.0


def progress(args: argparse.Namespace, total_hint: int = 0, desc: str = "identify"):
    """A callable(done, total) drawing a tqdm bar on stderr, or None.

    The bar shows when stderr is a terminal and ``--quiet`` was not given, and only
    once the run has taken :data:`PROGRESS_DELAY` seconds; otherwise nothing is
    printed (logs and pipes stay clean).
    """
    if getattr(args, "quiet", False) or not sys.stderr.isatty():
        return None
    state: dict = {"bar": None}

    def report(done: int, total: int) -> None:
        bar = state["bar"]
        if bar is None:
            from tqdm import tqdm  # loaded only when a bar is drawn

            bar = state["bar"] = tqdm(
                total=max(total, total_hint, 1),
                desc=desc,
                unit=" samples",
                file=sys.stderr,
                delay=PROGRESS_DELAY,
                leave=False,
                dynamic_ncols=True,
            )
        if total > bar.total:
            bar.total = total
        bar.update(max(done - bar.n, 0))
        if done >= total:
            bar.close()

    return report


# ------------------------------------------------------- numbers and columns
def parse_floats(text: str, what: str, n: int | None = None) -> list[float]:
    """``"1.5,2,3"`` -> [1.5, 2.0, 3.0] (``n`` values when given), with a clear error."""
    try:
        values = [float(x) for x in str(text).split(",") if x.strip()]
    except ValueError:
        raise InputError(
            f"{what} expects numbers separated by commas, got {shorten(text)!r}"
        ) from None
    if not values:
        raise InputError(f"{what} expects at least one number, got {shorten(text)!r}")
    if n is not None and len(values) != n:
        raise InputError(
            f"{what} takes {n} comma-separated numbers, got {len(values)}: {shorten(text)!r}"
        )
    if not all(math.isfinite(v) for v in values):
        raise InputError(f"{what} takes finite numbers, got {shorten(text)!r}")
    return values


def column_map(specs: list[str]) -> dict | None:
    """``["t=stamp", "q=pos*", "tau=3,4,5"]`` -> a column map for :func:`load_dataset`."""
    if not specs:
        return None
    out: dict = {}
    for spec in specs:
        field, sep, cols = spec.partition("=")
        if not sep or not field.strip() or not cols.strip():
            raise InputError(f"--column expects FIELD=COLUMNS, e.g. q='pos*', got {spec!r}")
        names = [c.strip() for c in cols.split(",") if c.strip()]
        items: list[int | str] = [int(c) if c.lstrip("-").isdigit() else c for c in names]
        field = field.strip()
        out[field] = items if field in ("joint_names",) or len(items) > 1 else items[0]
    return out


# ------------------------------------------------------------------ Dask
def add_scheduler_argument(parser, what: str) -> None:
    """``--scheduler SPEC`` (shared by the commands that accumulate on Dask); ``what``
    ends the help: what one task is and where the solve happens."""
    parser.add_argument(
        "--scheduler",
        metavar="SPEC",
        default=None,
        help="accumulate on Dask: local[:N] (a local cluster of N workers on 127.0.0.1, default "
        "2), tcp://HOST:PORT (a running scheduler) or SCHEDULER.json (its scheduler file); " + what,
    )


# ---------------------------------------------------- data files of identify
def add_file_arguments(parser: argparse.ArgumentParser) -> None:
    """The data-file options of ``manip-id identify`` (besides --data and --validate)."""
    g = parser.add_argument_group("data files (--data, --validate)")
    g.add_argument(
        "--window",
        metavar="START:STOP",
        default=None,
        help="window of every file given without one: seconds from the file's first stamp "
        "(2.5:30, :30, 2.5:) or rows (#1000:#5000); a file takes its own as FILE@START:STOP",
    )
    g.add_argument(
        "--torque-scale",
        metavar="G[,G...]",
        default=None,
        help="multiply the torque columns: one gain, or one per joint (drive gains from "
        "current [A] to torque [N m], gear ratios); recorded in the JSON",
    )
    g.add_argument(
        "--torque-scale-from",
        metavar="RESULT.json",
        default=None,
        help="the drive gains of 'manip-id drive-gains --json' as --torque-scale",
    )
    g.add_argument(
        "--velocity-deadband",
        type=float,
        metavar="EPS",
        default=None,
        help="leave out the rows of joint j where |dq_j| < EPS [rad/s] (standstill, where the "
        "Coulomb term sign(dq) is noise); the JSON counts them per joint",
    )
    g.add_argument(
        "--topic",
        default=None,
        help="ROS bags: the sensor_msgs/msg/JointState topic [default: the only one]",
    )
    g.add_argument(
        "--drop-bad-rows",
        action="store_true",
        help="drop (and count per reason) bad rows instead of refusing the file: NaN/Inf, "
        "values beyond the plausible magnitudes of their unit, malformed CSV lines, "
        "corrupted time stamps and isolated position spikes (running median) "
        "[default: refuse; a truncated last CSV line is always dropped, with a note]",
    )


def add_stream_arguments(
    parser: argparse.ArgumentParser, trim: bool = True, rate: bool = True
) -> None:
    """``--delay``, ``--time-unit``, ``--transmission``, (``rate``) ``--rate`` and
    (``trim``) ``--trim-standstill``."""
    g = parser.add_argument_group("streams (the audit's findings)")
    g.add_argument(
        "--delay",
        metavar="SECONDS[,...]",
        default=None,
        help="the torque stream lags the motion stream by SECONDS (one value, or one per "
        "joint): each row takes the torque logged SECONDS later (interpolated)",
    )
    g.add_argument(
        "--time-unit",
        choices=("s", "ms", "us", "ns"),
        default=None,
        help="unit of the files' time stamps [default s]",
    )
    if rate:
        g.add_argument(
            "--rate",
            type=float,
            metavar="HZ",
            default=None,
            help="sampling rate of files without a time column (t_k = k / HZ) [default: the "
            "files' own time column]",
        )
    g.add_argument(
        "--transmission",
        metavar="FILE.toml",
        default=None,
        help="the drive train: matrix R (theta = R (q - offset)), offset, signals = "
        '"motor" (the logs are motor-side, converted to the joints) or "joint", '
        "motor_terms [default: the robot profile's [transmission], else none]",
    )
    if trim:
        g.add_argument(
            "--trim-standstill",
            action="store_true",
            help="keep each file from the first to the last row where a joint moves "
            "(the JSON records the windows kept)",
        )


def spec_options(args: argparse.Namespace) -> dict:
    """The :class:`~manip_id.datasets.FileSpec` keywords of the stream options."""
    delay = getattr(args, "delay", None)
    values = None if delay is None else parse_floats(delay, "--delay")
    return {
        "time_unit": getattr(args, "time_unit", None),
        "delay": None if values is None else tuple(values),
        "rate": getattr(args, "rate", None),
        "transmission": transmission_option(args),
    }


def transmission_option(args: argparse.Namespace):
    """The ``--transmission`` file read once (kept on ``args``), or None."""
    value = getattr(args, "transmission", None)
    if value is None or isinstance(value, Transmission):
        return value
    args.transmission = load_transmission(value)
    return args.transmission


def cutoff_value(text: str) -> float | str:
    """``--cutoff``: a frequency [Hz] or ``auto`` (from each file's velocity spectrum)."""
    if str(text).strip().lower() == "auto":
        return "auto"
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a frequency [Hz] or 'auto', got {text!r}"
        ) from None
    return value


def file_specs(values, args: argparse.Namespace, colmap) -> list:
    """The file specs (path, window, columns, topic, time unit, delay) of ``--data`` /
    ``--validate`` values."""
    extra = spec_options(args)  # --time-unit, --delay
    return [
        parse_file_spec(v, window=args.window, columns=colmap, topic=args.topic, **extra)
        for v in values or []
    ]


def data_column_map(args: argparse.Namespace, profile) -> dict | None:
    """``--column`` maps, else the robot profile's [data] columns, else None."""
    colmap = column_map(args.column)
    if colmap is None and profile is not None and profile.columns:
        colmap = dict(profile.columns)
        unknown = [k for k in colmap if k not in (*FIELDS, "joint_names")]
        if unknown:
            raise InputError(
                f"profile {profile.source or profile.name}: unknown key "
                f"data.columns.{shorten(unknown[0])!r}; expected some of "
                f"{[*FIELDS, 'joint_names']}"
            )
    return colmap


# ------------------------------------------------------- consistent, export


def finish(args: argparse.Namespace, outputs, report_path=None) -> int:
    """Publish every output together, then say where they are; the exit status (0)."""
    outputs.publish()  # all outputs appear together, once all are complete
    if getattr(args, "json", None):
        print(f"wrote {args.json}")
    for value in (getattr(args, "export_urdf", None), getattr(args, "export_mjcf", None)):
        if value:
            print(f"wrote {value} and its sidecar")
    if report_path is not None:
        print(f"wrote the report to {report_path}/index.html")
    return 0


#: The simulation's defaults of ``identify --simulate`` (duration [s], rate [Hz], noise, seed).
SIM_DEFAULTS = {"duration": 20.0, "rate": 200.0, "noise": 0.01, "seed": 0}
#: The estimators that accumulate sums (files on Dask, --per-file).
FLEET_METHODS = ("ols", "wls")


def exports_wanted(args: argparse.Namespace) -> bool:
    """Whether the run writes a URDF or an MJCF export."""
    return bool(getattr(args, "export_urdf", None) or getattr(args, "export_mjcf", None))


def note_window(report: dict, result, window_length) -> None:
    """Record and print the energy / momentum window a run used (``result.context["window"]``:
    the given ``window_length`` [s], or the one chosen from the data)."""
    window = result.context.get("window") or {}
    report["window_length"] = window.get("length", window_length)  # the one used [s]
    if window:
        report["window"] = window
        how = "chosen from the data: " + window["rule"] if window["chosen"] else "given"
        print(f"window: {window['length']:.4g} s ({window['samples']} sampling intervals; {how})")


def fleet_wanted(args: argparse.Namespace) -> bool:
    """Whether an identify run sends the files as tasks (a scheduler or per-file estimates)."""
    return getattr(args, "scheduler", None) is not None or bool(getattr(args, "per_file", False))


def prepare(ds, args: argparse.Namespace, what: str):
    """The dataset preprocessed when ddq is missing or a cut-off was asked for."""
    if ds.ddq is not None and args.cutoff is None and args.decimate == 1 and args.trim is None:
        return ds
    cutoff = DEFAULT_CUTOFF if args.cutoff is None else args.cutoff
    try:
        if cutoff == "auto":  # from the positions' velocity spectrum (signals.bandwidth)
            choice = choose_cutoff(ds.t, ds.q, decimate=args.decimate)
            print(f"{what}: cut-off {choice.cutoff:.3g} Hz ({choice.reason})")
            cutoff = choice.cutoff
        return preprocess(
            ds, cutoff=cutoff, order=args.order, decimate=args.decimate, trim=args.trim
        )
    except InputError as exc:
        raise InputError(f"{what}: {exc}") from exc


def check_preprocess_args(args: argparse.Namespace) -> None:
    """The checks of the preprocessing and streaming options (``--cutoff``, ``--trim``,
    ``--decimate``, ``--chunk``) that need no data."""
    c = args.cutoff
    if c is not None and c != "auto" and not (math.isfinite(c) and c > 0):
        raise InputError(f"--cutoff must be a positive frequency [Hz] or auto, got {c}")
    if args.trim is not None and not (math.isfinite(args.trim) and args.trim >= 0):
        raise InputError(f"--trim must be >= 0 seconds, got {args.trim}")
    if args.decimate < 1:
        raise InputError(f"--decimate must be >= 1, got {args.decimate}")
    if args.chunk < 1:
        raise InputError(f"--chunk must be >= 1, got {args.chunk}")


def identify_report(name: str):
    """The function ``name`` (``write_identify_report``, ``write_fleet_report``) of
    :mod:`manip_id.viz.identify_report`, imported only when a report is written: that
    module loads matplotlib and meshcat (about 0.3 s and 40 MB at start-up) which a run
    without ``--report`` never needs."""
    return getattr(importlib.import_module("manip_id.viz.identify_report"), name)


def command(module: str):
    """The run function of a command, in ``module`` (``manip_id.cli._identify``),
    imported when the command runs: that module loads Pinocchio and the identification,
    which ``manip-id --help`` never needs."""

    def run(args: argparse.Namespace) -> int:
        return importlib.import_module(module).run(args)

    return run


def add_quiet_verbose(parser: argparse.ArgumentParser, verbose_help: str) -> None:
    """``--quiet`` (nothing on stdout: no tables, no bar; errors and warnings stay on
    stderr) or ``--verbose`` (``verbose_help``), one of them: the same words in every
    command that prints an answer."""
    g = parser.add_mutually_exclusive_group()
    g.add_argument(
        "--quiet",
        action="store_true",
        help="print nothing but errors and warnings (no progress bar, no tables)",
    )
    g.add_argument("--verbose", action="store_true", help=verbose_help)


def quiet_stdout(args: argparse.Namespace):
    """A context in which ``--quiet`` sends stdout nowhere (else it changes nothing)."""
    if getattr(args, "quiet", False):
        return contextlib.redirect_stdout(io.StringIO())
    return contextlib.nullcontext()
