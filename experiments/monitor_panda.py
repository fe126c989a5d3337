"""The collision monitor on the real Panda log: false alarms and detection delays.

    python experiments/monitor_panda.py [--data ../shared/data/panda_gaz2019] [--json OUT]

Identifies the log as ``manip-id identify panda --friction viscous,coulomb,offset
--split 0.7`` does, calibrates the bounds on the training part (false-alarm rate 1e-3 per
sample), then on the validation part prints, per observer setting: the alarm rate, the
largest ``|r_j| / b_j`` per joint, and for an external torque of 2 N m added to joint 4 for
0.5 s, starting every 0.25 s across the validation part: how many of the hits are found,
the detection delays (median, max), the peaks, and the detections outside the hits.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
from pathlib import Path

import numpy as np

from manip_id import load_robot
from manip_id.cli import main as manip_id_main
from manip_id.monitor import CollisionMonitor, calibrate_thresholds, load_model, read_log

FRICTION = "viscous,coulomb,offset"
SETTINGS = {
    "K = K2 = 25 /s (default)": {"gain": 25.0, "filter_gain": 25.0},
    "first-order, K = 25 /s": {"gain": 25.0, "filter_gain": None},
    "first-order, K = 10 /s": {"gain": 10.0, "filter_gain": None},
}
HIT, JOINT, SIZE = 0.5, 3, 2.0  # duration [s], panda_joint4, [N m]


def _hits(robot, model, th, valid, kw) -> dict:
    mon = CollisionMonitor(robot, model, th, **kw)
    starts = np.arange(valid.t[0] + 0.25, valid.t[-1] - HIT - 0.2, 0.25)
    delays, peaks, missed, extra = [], [], 0, 0
    for s in starts:
        tau = valid.tau.copy()
        tau[(valid.t >= s) & (valid.t < s + HIT), JOINT] -= SIZE
        dets = mon.run(valid.t, valid.q, valid.dq, tau).detections()
        ours = [d for d in dets if d.stop >= s and d.start <= s + HIT + 0.5]
        extra += len(dets) - len(ours)
        mine = [d for d in ours if "panda_joint4" in d.joints]
        if not mine:
            missed += 1
            continue
        delays.append(mine[0].start - s)
        peaks.append(mine[0].peak)
    return {
        "hits": len(starts),
        "found": len(starts) - missed,
        "delay_median_s": statistics.median(delays) if delays else None,
        "delay_max_s": max(delays) if delays else None,
        "peak_median": statistics.median(peaks) if peaks else None,
        "detections_outside_the_hits": extra,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--data", default=str(Path(__file__).parents[2] / "shared/data/panda_gaz2019")
    )
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        res = Path(folder) / "panda.json"
        argv = ["identify", "panda", "--data", args.data, "--friction", FRICTION, "--split", "0.7"]
        if manip_id_main([*argv, "--json", str(res)]) != 0:
            raise SystemExit("identification failed")
        split = float(json.loads(res.read_text())["files"][0]["window"].lstrip(":"))
        robot = load_robot("panda", friction=FRICTION)
        model = load_model(robot, res)
    train = read_log(robot, f"{args.data}@:{split}")
    valid = read_log(robot, f"{args.data}@{split}:")
    out: dict = {"split_s": split, "settings": {}}
    for label, kw in SETTINGS.items():
        th = calibrate_thresholds(robot, model, [train], **kw)
        run = CollisionMonitor(robot, model, th, **kw).run(valid.t, valid.q, valid.dq, valid.tau)
        case = {
            "bounds": th.bound.round(4).tolist(),
            "calibration_rate": th.rate,
            "validation_alarm_rate": run.alarm_rate,
            "validation_detections": len(run.detections()),
            "validation_max_over_bound": (np.abs(run.residual).max(0) / th.bound).round(3).tolist(),
            **_hits(robot, model, th, valid, kw),
        }
        out["settings"][label] = case
        print(f"{label}:")
        for k, v in case.items():
            print(f"  {k}: {v}")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
