"""Rollout validation and output-error refinement on the real Panda log (Gaz et al. 2019).

Train on 0-10.5 s, validate on 10.5-15 s (each part preprocessed alone, as identify does).
Three models: plain least squares (OLS), the consistent least-squares estimate
(``--consistent``) and that estimate refined by output error (``identify --refine
output-error``). For each, the validation torque error and the rollout position error at
0.1, 0.25 and 0.5 s horizons (RMS over joints of the per-joint RMS at the horizon), with
the nominal model beside them. The same runs as commands::

    D=../shared/data/panda_gaz2019
    manip-id identify panda --friction viscous,coulomb,offset --data $D@0:10.5 \\
        --validate $D@10.5:15 --json ls.json
    manip-id identify panda --friction viscous,coulomb,offset --consistent --data $D@0:10.5 \\
        --validate $D@10.5:15 --json cons.json
    manip-id identify panda --friction viscous,coulomb,offset --consistent --data $D@0:10.5 \\
        --validate $D@10.5:15 --refine output-error --json refined.json
    manip-id validate panda --model refined.json --data $D@10.5:15 --horizon 0.25

Usage::

    .venv/bin/python experiments/panda_rollout.py [--data FOLDER] [--horizon S ...]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from manip_id import load_robot
from manip_id.export import export_mjcf
from manip_id.export.mjcf_rollout import mujoco_rollout_gap
from manip_id.identification import (
    ConsistentOptions,
    FileOptions,
    PreprocessOptions,
    RefineOptions,
    RolloutOptions,
    identify,
    read_logs,
    refine,
    rollout_validation,
)
from manip_id.identification.forward import coulomb_width
from manip_id.identification.rollout import as_log

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "panda_gaz2019"
FRICTION = "viscous,coulomb,offset"


def rms(x) -> float:
    return float(np.sqrt(np.nanmean(np.asarray(x) ** 2)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(DATA))
    parser.add_argument("--horizon", type=float, nargs="+", default=[0.1, 0.25, 0.5])
    parser.add_argument("--refine-horizon", type=float, default=0.1)
    parser.add_argument("--starts", type=int, default=200)
    a = parser.parse_args()
    robot = load_robot("panda", friction=FRICTION)
    train_spec, valid_spec = f"{a.data}@0:10.5", f"{a.data}@10.5:15"
    options = PreprocessOptions()
    models = {}
    t0 = time.perf_counter()
    files = FileOptions(preprocess=options, audit=False)
    models["least squares"] = identify(
        robot, [train_spec], validation=[valid_spec], method="ols", files=files
    )
    t_ls = time.perf_counter() - t0
    t0 = time.perf_counter()
    models["consistent"] = identify(
        robot,
        [train_spec],
        validation=[valid_spec],
        method="ols",
        files=files,
        consistent=ConsistentOptions(),
    )
    t_cons = time.perf_counter() - t0
    train = read_logs(robot, [train_spec], options)
    valid = read_logs(robot, [valid_spec], options)
    t0 = time.perf_counter()
    models["refined"] = refine(
        models["consistent"],
        robot,
        train,
        validation=valid,
        options=RefineOptions(horizon=a.refine_horizon),
    )
    t_ref = time.perf_counter() - t0
    rec = models["refined"].context["refinement"]
    print(f"times: least squares {t_ls:.1f} s, consistent {t_cons:.1f} s, refine {t_ref:.1f} s")
    print(
        f"refinement: {rec['windows']} windows of {rec['horizon']:.3f} s, "
        f"{rec['iterations']} iterations, output error {rec['cost_before']:.4g} -> "
        f"{rec['cost_after']:.4g}, torque RSS {rec['torque_rss_before']:.4g} -> "
        f"{rec['torque_rss_after']:.4g}"
    )
    print("\nvalidation torque error (relative, filtered torques):")
    for name, m in models.items():
        print(f"  {name:<14} {100 * m.relative_error.validation:6.3f} %")
    nominal = models["least squares"].relative_error.nominal_validation
    if nominal is not None:
        print(f"  {'nominal':<14} {100 * nominal:6.3f} %")
    print("\nrollout position error at the horizon [rad] (RMS over joints; diverged rollouts)")
    print(f"  {'horizon':>8} " + " ".join(f"{n:>20}" for n in [*models, "nominal"]))
    for h in a.horizon:
        opts = RolloutOptions(horizon=h, starts=a.starts)
        cells, nom = [], None
        for m in models.values():
            rep = rollout_validation(robot, m, valid, options=opts)
            e = rep.identified
            cells.append(f"{rms(e.position_rms):12.4g} ({e.diverged:3d})")
            nom = rep.nominal
        assert nom is not None
        cells.append(f"{rms(nom.position_rms):12.4g} ({nom.diverged:3d})")
        print(f"  {h:8.2f} " + " ".join(f"{c:>20}" for c in cells))
    mjcf_gap(robot, models["consistent"], valid, a.horizon, a.starts)


def mjcf_gap(robot, result, valid, horizons, starts: int) -> None:
    """The consistent model exported as MJCF and rolled out in MuJoCo (contacts off)
    against the Pinocchio rollout of the same standard parameters."""
    try:
        import mujoco  # noqa: F401
    except ImportError:
        print("\nMuJoCo not installed: no MJCF rollout")
        return
    theta = result.standard.values
    log = as_log(valid[0])
    eps = coulomb_width(robot, theta, log.q[::50], log.dt)
    print("\nexported MJCF in MuJoCo vs Pinocchio (consistent model) [rad, RMS over joints]")
    print(f"  {'horizon':>8} {'|q_mj - q_pin|':>16} {'MuJoCo vs log':>14} {'Pinocchio vs log':>17}")
    with tempfile.TemporaryDirectory() as tmp:
        path = export_mjcf(robot, theta, Path(tmp) / "panda.xml").path
        for h in horizons:
            g = mujoco_rollout_gap(path, robot, theta, log, horizon=h, eps=eps, starts=starts)
            print(
                f"  {h:8.2f} {rms(g.gap_rms):16.4g} {rms(g.mujoco_rms):14.4g} "
                f"{rms(g.pinocchio_rms):17.4g}"
            )


if __name__ == "__main__":
    main()
