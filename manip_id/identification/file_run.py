"""Log files -> a problem, with everything a file run does before the fit.

The pipeline behind ``identify(robot, ["a.csv", "b.npz@2:30"])`` and ``manip-id identify
--data``, the same for both:

    1. temperature        a file lacking the temperature the robot's law needs is refused
    2. pre-fit audit      every file checked (timing, units, delay, standstill), its table
                          in the result (``audit``); optionally trimmed to where it moves
    3. scans              each file read once: rows checked, its data-quality summary
                          (``split``: one file cut into training and validation windows)
    4. reference          the temperature law's ``T0``: the training files' mean
    5. friction           ``select_friction``: the joint model chosen per joint
    6. accumulate         least squares: each file in chunks (here, forked, or Dask tasks);
                          online laws: the files in memory, in sample order
    7. context            source, preprocessing, reference torques, per-file records

With a scheduler or ``partition.per_file`` each file (each block) is one task
(:func:`~manip_id.identification.files.distributed_files_problem`): the tasks scan their
own files, so that path runs no pre-fit audit. What the run finds on the way is said
through ``RunOptions.echo`` as it is found.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from types import SimpleNamespace

import numpy as np

from .._io.files import same_file
from ..audit import AuditOptions, audit_files
from ..datasets import Layout, RowCache, load_dataset
from ..datasets.stream import torque_scale_vector
from ..errors import InputError
from ..identifiability import BaseParameters
from ..robot.model import Robot
from .arrays import CallOptions, samples_problem
from .closed_loop import (
    ClosedLoopOptions,
    check_closed_loop,
    closed_loop_estimate,
    closed_loop_logs,
)
from .data_sources import Samples
from .files import distributed_files_problem, files_problem
from .options import (
    LEAST_SQUARES,
    PreprocessOptions,
    RunOptions,
    SolveSettings,
    check_least_squares,
)
from .problem import FileRecord, Problem, resolve_base
from .reading import iter_processed, scan_file, split_file
from .refine import RefineOptions, refine
from .result import IdentificationResult
from .rollout import RolloutOptions, read_logs, rollout_validation
from .run_context import RunContext, file_keys, raw_reference, run_keys
from .selection import SelectionOptions, select_model_files
from .solve import solve
from .tasks import PartitionOptions, file_specs
from .temperature import (
    check_scans_temperature,
    check_sources_temperature,
    note_reference,
    reference_from_files,
    reference_from_scans,
    reference_text,
)


@dataclass(frozen=True)
class FileOptions:
    """How log files are read, checked and modelled (one set for every file of a run).

    Attributes
    ----------
    preprocess : PreprocessOptions
        Filtering, torque scale, velocity deadband, bad rows.
    window : str or None
        Window of every file given without one: ``START:STOP`` [s from the file's first
        stamp] or ``#A:#B`` [rows].
    audit : bool
        Run the pre-fit audit (timing, units, delays, standstill) before the fit.
    trim_standstill : bool
        Keep each file from the first to the last row where a joint moves (needs ``audit``).
    split : float or None
        Identify on the first ``split`` of the one training file's samples, validate on the
        rest (no validation files then).
    partition : PartitionOptions or None
        Each file (``block``: each block of samples) one task, and with ``per_file`` each
        file's own estimate (``result.per_file``); also chosen by ``RunOptions.scheduler``.
    select_friction : SelectionOptions or None
        Choose the friction law per joint (one fit per candidate; least squares and the
        dynamic model); None: the robot's joint terms.
    refine : RefineOptions or None
        Refine the least-squares estimate by output error on the training files
        (:mod:`~manip_id.identification.refine`; ``context["refinement"]``).
    rollout : RolloutOptions or None
        Roll the identified and the nominal model forward on the validation files
        (:mod:`~manip_id.identification.rollout`): ``result.rollout`` and
        ``context["rollout"]``. Both need least squares, the dynamic model, one process.
    closed_loop : ClosedLoopOptions or None
        Closed-loop logs with a known controller: IDIM-IV or DIDIM
        (:mod:`~manip_id.identification.closed_loop`) from the least-squares estimate of
        ``method`` (``"ols"`` for the classical start), ``context["closed_loop"]``; the
        logs hold the controller's reference columns. Not with ``refine``.
    """

    preprocess: PreprocessOptions = field(default_factory=PreprocessOptions)
    window: str | None = None
    audit: bool = True
    trim_standstill: bool = False
    split: float | None = None
    partition: PartitionOptions | None = None
    select_friction: SelectionOptions | None = None
    refine: RefineOptions | None = None
    rollout: RolloutOptions | None = None
    closed_loop: ClosedLoopOptions | None = None

    def __post_init__(self):
        if not isinstance(self.preprocess, PreprocessOptions):
            raise InputError(
                f"preprocess must be PreprocessOptions, got {type(self.preprocess).__name__}"
            )
        if self.split is not None and not 0.0 < float(self.split) < 1.0:
            raise InputError(f"split must be a fraction in (0, 1), got {self.split}")
        if self.trim_standstill and not self.audit:
            raise InputError("trim_standstill needs the pre-fit audit (audit=True)")
        if self.closed_loop is not None and self.refine is not None:
            raise InputError(
                "closed_loop (iv, didim) and refine both replace the estimate: give one"
            )

    def distributed(self, run: RunOptions) -> bool:
        """Whether the files are tasks (a scheduler, blocks, or per-file estimates)."""
        part = self.partition
        return run.scheduler is not None or (
            part is not None and (part.per_file or bool(part.block))
        )


def collect(robot: Robot, specs, options, scans) -> SimpleNamespace:
    """The preprocessed files in memory, one after the other (time shifted to increase):
    ``t, q, dq, ddq, tau[, temp]``, ``n_samples``, the preprocessing ``settings`` and
    ``counts``, the samples of each file."""
    nq, nv = robot.nq, robot.nv
    parts: list[np.ndarray] = []
    settings = None
    for spec in specs:
        s, blocks = iter_processed(robot, spec, options, scans.get(spec))
        settings = settings or s
        rows = np.vstack(list(blocks))
        if rows.shape[1] < 1 + nq + 3 * nv:
            raise InputError(f"{spec.label}: no accelerations")
        if parts:
            prev = parts[-1]
            step = float(np.median(np.diff(rows[:, 0]))) if rows.shape[0] > 1 else 1.0
            rows = rows.copy()
            rows[:, 0] += prev[-1, 0] + step - rows[0, 0]
        parts.append(rows)
    rows = np.vstack(parts)
    f = Layout.processed(nq, nv, rows.shape[1]).unpack(rows)
    fields: dict = {"temp": None, **f}  # temp: the temperature law's, when measured
    counts = [p.shape[0] for p in parts]
    return SimpleNamespace(**fields, n_samples=rows.shape[0], settings=settings, counts=counts)


def _records(robot: Robot, specs, data, scans, options) -> list[FileRecord]:
    """The records of files held in memory (:func:`collect`): nothing left out."""
    scale = torque_scale_vector(options.torque_scale, robot.nv, "torque_scale")
    return [
        FileRecord(s, n, np.zeros(robot.nv, dtype=int), scans[s].quality, data.settings, scale)
        for s, n in zip(specs, data.counts, strict=True)
    ]


def _scan(robot: Robot, specs, vspecs, fopts: FileOptions, run: RunOptions, timings: dict):
    """The pre-fit audit, then each training and validation file scanned (``split``: the
    one file cut first). A slow format (CSV, ROS bags) is parsed once: the audit's pass
    records its rows, which the scans read back."""
    options = fopts.preprocess
    check_sources_temperature(robot, specs + (vspecs or []))  # before the audit's output
    audit = None
    with RowCache() as cache:
        t0 = time.perf_counter()
        if fopts.audit:
            audit = audit_files(robot, specs + (vspecs or []), _audit_options(options), cache=cache)
            if run.verbose or audit.findings:  # a clean audit: one line in the answer
                run.say(audit.text(verbose=run.verbose))
            if fopts.trim_standstill:
                trimmed = audit.trimmed()
                specs, vspecs = (
                    trimmed[: len(specs)],
                    None if vspecs is None else trimmed[len(specs) :],
                )
                run.say("--trim-standstill: " + ", ".join(s.label for s in trimmed))
            timings["audit"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        scans = {s: scan_file(robot, s, options, cache=cache) for s in specs + (vspecs or [])}
        source: dict = {"data": [s.label for s in specs]}
        if vspecs is None and fopts.split is not None:
            train, valid = split_file(
                robot, specs[0], fopts.split, options, scans[specs[0]], cache=cache
            )
            for old in scans.values():
                old.discard()
            specs, vspecs = [train], [valid]
            scans = {s: scan_file(robot, s, options, cache=cache) for s in specs + vspecs}
            source["split"] = fopts.split
    if vspecs is not None:
        source["validate"] = [s.label for s in vspecs]
        source.update(shared_files(specs, vspecs))
    timings["scan"] = time.perf_counter() - t0
    for s in specs if run.verbose else ():  # else in the result's files only
        run.say(scans[s].quality.text())
    for s in (vspecs or []) if run.verbose else ():
        run.say("validation " + scans[s].quality.text())
    return SimpleNamespace(specs=specs, vspecs=vspecs, scans=scans, source=source, audit=audit)


def with_transmission(robot: Robot, specs):
    """``specs`` with the robot's drive train (its profile's or ``--transmission``) on each
    spec that names none (None stays None)."""
    if specs is None or robot.transmission is None:
        return specs
    return [s if s.transmission else replace(s, transmission=robot.transmission) for s in specs]


def shared_files(specs, vspecs) -> dict:
    """``{"validation_in_training": [[validation label, training label], ...]}`` for each
    validation file that is also a training file (the same file, both whole or with the
    same window): its validation error would be measured on training data. Else {}."""
    pairs = [
        [v.label, s.label]
        for v in vspecs or ()
        for s in specs
        if same_file(v.path, s.path) and v.window == s.window
    ]
    return {"validation_in_training": pairs} if pairs else {}


def _audit_options(options: PreprocessOptions) -> AuditOptions:
    return AuditOptions(
        torque_scale=options.torque_scale,
        drop_bad_rows=options.drop_bad_rows,
        standstill=options.velocity_deadband,
        cutoff=options.cutoff if isinstance(options.cutoff, float) else None,  # auto: its own
    )


def _selection_keys(robot: Robot, selection) -> dict:
    """The selection's keys in the context (the same as select_model's result context)."""
    keys = {
        "friction_selection": selection.to_dict(),
        "friction_criterion": selection.criterion,
        "joint_terms_per_joint": dict(
            zip(robot.dof_names, map(list, selection.terms.per_dof or ()), strict=True)
        ),
    }
    if selection.terms.shapes is not None:
        keys["friction_shapes"] = selection.terms.shapes.to_dict()
    return keys


def _select_friction(robot, f, fopts: FileOptions, settings: SolveSettings, run, timings):
    """The joint model chosen per joint (plain least squares per candidate; the consistent
    estimate, if any, applies to the chosen model); ``(robot, context keys)``."""
    t0 = time.perf_counter()
    lean = RunOptions(chunk=run.chunk, workers=run.workers)
    plain = replace(settings, consistent=None)

    def fit(r: Robot) -> IdentificationResult:
        base = resolve_base(r, None, {})
        return solve(
            files_problem(
                r, f.specs, f.vspecs, base, fopts.preprocess, run=lean, scans=f.scans
            ),  # fmt: skip
            plain.method,
        )

    robot, selection = select_model_files(
        robot, fit, f.specs, f.vspecs, f.scans, selection=fopts.select_friction
    )
    timings["friction_selection"] = time.perf_counter() - t0
    run.say(selection.text())
    return robot, _selection_keys(robot, selection)


def _raw_parts(specs, vspecs, train, valid, options) -> list:
    """``(name, processed, t_raw, tau_raw)`` of one training (and one validation) file for
    :func:`~manip_id.identification.run_context.raw_reference`; [] for several files."""
    if len(specs) != 1 or (vspecs is not None and len(vspecs) != 1):
        return []
    parts, raws = [], {}
    for name, spec, proc in (
        ("train", specs[0], train),
        ("validation", (vspecs or [None])[0], valid),
    ):
        if spec is None:
            continue
        key = (str(spec.path), spec.topic)
        if key not in raws:
            raws[key] = load_dataset(
                spec.path,
                format=spec.format,
                columns=spec.columns,
                topic=spec.topic,
                rate=spec.rate,
            )
        raw, tr = raws[key], spec.transmission
        tau = raw.tau if tr is None or tr.signals == "joint" else tr.to_joint(tau_motor=raw.tau)[3]
        scale = 1.0 if options.torque_scale is None else np.asarray(options.torque_scale)
        parts.append((name, proc, raw.t, tau * scale))
    return parts


def _online_problem(robot: Robot, f, base, settings, opts: CallOptions, options, timings):
    """The online laws' problem (the files preprocessed in memory, in sample order, their
    records, the errors against the raw torques as a post-step) and the preprocessing."""
    run = opts.run
    t0 = time.perf_counter()
    train = collect(robot, f.specs, options, f.scans)
    valid = None if f.vspecs is None else collect(robot, f.vspecs, options, f.scans)
    timings["preprocess"] = time.perf_counter() - t0
    samples = Samples(train.q, train.dq, train.ddq, train.tau, train.temp)
    vsamples = (
        None if valid is None else Samples(valid.q, valid.dq, valid.ddq, valid.tau, valid.temp)
    )
    problem = samples_problem(
        robot, samples, None if vsamples is None else vsamples.arrays(), base, settings, opts
    )
    problem.timings.update(timings)
    problem.files = {
        "train": _records(robot, f.specs, train, f.scans, options),
        "validation": None if valid is None else _records(robot, f.vspecs, valid, f.scans, options),
    }
    parts = _raw_parts(f.specs, f.vspecs, train, valid, options)

    def raw(result: IdentificationResult) -> IdentificationResult:
        result.context.update(raw_reference(robot, result, parts, run.chunk))
        return result

    problem.post.append(raw)
    return problem, train.settings


def files_build(
    robot: Robot,
    files: list,
    validation: list | None,
    base: BaseParameters | None,
    settings: SolveSettings,
    opts: CallOptions,
    fopts: FileOptions,
) -> Problem:
    """The problem of log files ``files`` (and ``validation`` files), with the file run's
    context (module docstring)."""
    t_start = time.perf_counter()
    run = opts.run
    specs = file_specs(files, "data", fopts.window)
    records: dict | None
    vspecs = None if validation is None else file_specs(validation, "validation", fopts.window)
    specs, vspecs = with_transmission(robot, specs), with_transmission(robot, vspecs)
    forward = fopts.refine is not None or fopts.rollout is not None
    forward = forward or fopts.closed_loop is not None
    if forward and (
        fopts.distributed(run)
        or opts.model.name != "dynamic"
        or settings.method not in LEAST_SQUARES
    ):
        raise InputError(
            "refine, rollout and the closed-loop estimators (iv, didim) need a least-squares "
            "start (ols, wls), the dynamic model and one process (no scheduler, blocks or "
            "per-file estimates)"
        )
    if fopts.closed_loop is not None:
        check_closed_loop(robot, fopts.closed_loop, specs)  # the training files hold a reference
    if fopts.distributed(run) or opts.model.name != "dynamic":
        return _distributed(robot, specs, vspecs, base, settings, opts, fopts)
    if fopts.split is not None and (len(specs) != 1 or vspecs is not None):
        raise InputError(
            f"split cuts one file without validation files; got {len(specs)} training file(s)"
            + ("" if vspecs is None else f" and {len(vspecs)} validation file(s)")
        )
    if fopts.select_friction is not None:
        check_least_squares(settings.method, "the friction selection fits")
    timings: dict[str, float] = {}
    options = fopts.preprocess
    f = _scan(robot, specs, vspecs, fopts, run, timings)
    for s in f.specs + (f.vspecs or []):
        scan = f.scans[s]
        if scan.cutoff is not None:
            run.say(f"{s.label}: cut-off {scan.cutoff.cutoff:.3g} Hz ({scan.cutoff.reason})")
        if scan.derived_velocity:
            run.say(f"{s.label}: no velocities in the file: dq differentiated from the filtered q")
    check_scans_temperature(robot, [f.scans[s] for s in f.vspecs or []])
    robot = reference_from_scans(robot, [f.scans[s] for s in f.specs])  # the law's T0
    if (text := reference_text(robot)) is not None:
        run.say(text)
    keys: dict = {} if f.audit is None else {"audit": f.audit.to_dict()}
    if fopts.select_friction is not None:
        robot, chosen = _select_friction(robot, f, fopts, settings, run, timings)
        keys.update(chosen)
    if settings.method in LEAST_SQUARES:
        base = resolve_base(robot, base, timings)
        problem = files_problem(
            robot, f.specs, f.vspecs, base, options, window=None, run=run, scans=f.scans,
            uncertainty=settings.uncertainty, timings=timings,
        )  # fmt: skip
        problem.settings = settings
        problem.post.append(lambda result: note_reference(result, robot))
        problem.post += _forward_steps(robot, f, fopts, run)
        records = problem.files or {}
        preprocess = records["train"][0].settings
        n_valid = sum(x.n_samples for x in records["validation"] or [])
    else:  # the online laws: the files in memory, in sample order
        problem, preprocess = _online_problem(robot, f, base, settings, opts, options, timings)
        records = problem.files or {}
        n_valid = sum(x.n_samples for x in records["validation"] or [])
    problem.t_start = t_start
    ctx = RunContext(source=f.source, n_validation=n_valid, settings=preprocess)
    problem.context.update(run_keys(robot, None, ctx))
    problem.context.update(
        file_keys(robot, f.specs, f.vspecs, _qualities(f.scans), records, options)
    )
    problem.context.update(keys)
    return problem


def _forward_steps(robot: Robot, f, fopts: FileOptions, run: RunOptions) -> list:
    """The post-steps of a least-squares file run that integrate the model forward: the
    output-error refinement on the training files, then the rollout on the validation
    files (each reads its files again, preprocessed as the fit read them)."""
    options, steps = fopts.preprocess, []
    start: dict = {}  # the estimate the refinement started from (rolled out beside it)
    if fopts.closed_loop is not None:
        copts = fopts.closed_loop

        def estimated(result: IdentificationResult) -> IdentificationResult:
            t0 = time.perf_counter()
            train = closed_loop_logs(robot, f.specs, options, copts.controller)
            valid = read_logs(robot, f.vspecs, options) if f.vspecs else None
            out = closed_loop_estimate(result, robot, train, options=copts, validation=valid)
            rec = out.context["closed_loop"]
            state = "converged" if rec["converged"] else "NOT converged"
            last = rec["history"][-1]["step"]
            run.say(
                f"{copts.method}: {rec['iterations']} iterations from {rec['start']}, {state} "
                f"(last relative step {last:.2g}, tolerance {rec['tolerance']:.2g})"
            )
            out.timings["closed_loop"] = time.perf_counter() - t0
            return out

        steps.append(estimated)
    if fopts.refine is not None:
        ropts = fopts.refine

        def refined(result: IdentificationResult) -> IdentificationResult:
            start["result"] = result
            t0 = time.perf_counter()
            train = read_logs(robot, f.specs, options)
            valid = read_logs(robot, f.vspecs, options) if f.vspecs else None
            out = refine(result, robot, train, validation=valid, options=ropts)
            rec = out.context["refinement"]
            run.say(
                f"output-error refinement: {rec['windows']} windows of {rec['horizon']:.3g} s, "
                f"{rec['iterations']} iterations, cost {rec['cost_before']:.4g} -> "
                f"{rec['cost_after']:.4g}"
            )
            out.timings["refine"] = time.perf_counter() - t0
            return out

        steps.append(refined)
    if fopts.rollout is not None:
        if not f.vspecs:
            raise InputError("a rollout integrates on validation data: give validation or split")
        oopts = fopts.rollout

        def rolled(result: IdentificationResult) -> IdentificationResult:
            logs = read_logs(robot, f.vspecs, options)
            rep = rollout_validation(robot, result, logs, options=oopts)
            run.say(rep.table())
            result.context["rollout"] = rep.to_dict()
            if "result" in start:  # refined: the start's rollout beside it, and a word if worse
                before = rollout_validation(robot, start["result"], logs, options=oopts)
                result.context["rollout"]["before_refinement"] = before.identified.to_dict()
                if (text := refinement_worse(rep, before)) is not None:
                    result.context.setdefault("warnings", []).append(text)
            return replace(result, rollout=rep)

        steps.append(rolled)
    return steps


#: A refined model whose validation rollout error exceeds its start's by this factor is
#: named in a warning.
REFINEMENT_WORSE = 1.05


def refinement_worse(after, before) -> str | None:
    """The warning when the output-error refinement made the validation rollout worse
    (position RMS over the joints at the horizon, of two
    :class:`~manip_id.identification.rollout.RolloutReport` s), else None."""
    a = float(np.linalg.norm(after.identified.position_rms))
    b = float(np.linalg.norm(before.identified.position_rms))
    if not (np.isfinite(a) and np.isfinite(b)) or a <= REFINEMENT_WORSE * b:
        return None
    return (
        f"the output-error refinement made the validation rollout worse: position error "
        f"{a:.4g} rad at {after.horizon:g} s against {b:.4g} rad before it (fit on the "
        "training windows, it does not carry to these data); keep the unrefined model "
        "(leave out --refine) or refine over the horizon you validate (--refine-horizon)"
    )


def _qualities(scans: dict) -> dict:
    return {spec: scan.quality for spec, scan in scans.items()}


def _distributed(robot, specs, vspecs, base, settings: SolveSettings, opts, fopts: FileOptions):
    """Each file (each block) one task on the run's back-end; no pre-fit audit (the tasks
    scan their own files)."""
    t_start = time.perf_counter()
    run, model = opts.run, opts.model
    check_least_squares(settings.method, "files as tasks (a scheduler, blocks, per-file) are")
    for what, bad in (
        ("select_friction", fopts.select_friction is not None),
        ("split", fopts.split is not None),
        ("trim_standstill", fopts.trim_standstill),
    ):
        if bad:
            raise InputError(
                f"{what} needs the files read here: not with a scheduler, blocks, per-file "
                "estimates or the energy / momentum model"
            )
    options = fopts.preprocess
    robot, _, made = reference_from_files(robot, specs, vspecs, options)  # the law's T0
    for scan in made:  # (the tasks scan their files themselves)
        scan.discard()
    timings: dict[str, float] = {}
    base = resolve_base(robot, base, timings)
    problem = distributed_files_problem(
        robot, specs, vspecs, base, options, run=run, model=model,
        partition=fopts.partition, uncertainty=settings.uncertainty, timings=timings,
    )  # fmt: skip
    problem.settings = settings
    problem.t_start = t_start
    files = problem.files or {"train": [], "validation": None}
    for info in files["train"] if run.verbose else ():
        run.say(info.quality.text())
    for info in (files["validation"] or []) if run.verbose else ():
        run.say("validation " + info.quality.text())
    source = {"data": [s.label for s in specs], "scheduler": _scheduler_name(run.scheduler)}
    if vspecs is not None:
        source["validate"] = [s.label for s in vspecs]
        source.update(shared_files(specs, vspecs))
    n_valid = sum(x.n_samples for x in files["validation"] or [])
    ctx = RunContext(source=source, n_validation=n_valid, settings=files["train"][0].settings)
    qualities = {x.spec: x.quality for x in files["train"] + (files["validation"] or [])}
    problem.context.update(run_keys(robot, None, ctx))
    problem.context.update(file_keys(robot, specs, vspecs, qualities, files, options))
    if model.name != "dynamic":
        problem.context["window_length"] = model.window_length
    problem.post.insert(0, lambda result: note_reference(result, robot))
    return problem


def _scheduler_name(scheduler) -> str:
    """The scheduler in words (a text as given, a client by its class)."""
    if scheduler is None:
        return "this process"
    return scheduler if isinstance(scheduler, str) else type(scheduler).__name__


__all__ = ["FileOptions", "collect", "files_build"]
