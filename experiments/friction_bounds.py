"""What bounds the friction models on a real log: two measured floors.

1. Against the raw torques: the share of the raw torque above the preprocessing
   low-pass (``||tau_raw - F[tau_raw]|| / ||tau_raw||`` on the validation part, F the
   zero-phase Butterworth of :func:`manip_id.signals.preprocess`). A model fed by the
   filtered states cannot follow it, so it bounds the error against the raw torques.
2. Per joint: the best static law of ``(dq_j, q_j)`` on the residual of the chosen
   model (``--friction auto``): 40 velocity bins (training quantiles) and 6 harmonics of
   ``q_j``, fitted on the training residual and scored on the validation data. What is
   left is not a function of the joint's own velocity and angle.

Run: ``.venv/bin/python experiments/friction_bounds.py --data LOG --auto RESULT.json``
(RESULT.json from ``manip-id identify panda --data LOG --split 0.7 --friction auto
--json RESULT.json``), optionally ``--split 0.7 --cutoff 3 --joint 7``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from manip_id import load_robot  # noqa: E402
from manip_id.datasets import load_dataset  # noqa: E402
from manip_id.identification import identify  # noqa: E402
from manip_id.robot.friction import FrictionShapes  # noqa: E402
from manip_id.robot.model import JointTerms  # noqa: E402
from manip_id.signals import preprocess  # noqa: E402


def raw_floor(valid, cutoffs) -> dict:
    """Per cutoff [Hz]: the share of the raw torque above it, total and per joint."""
    out = {}
    for c in cutoffs:
        p = preprocess(valid, cutoff=c, filter_torque=True)
        nv = valid.tau.shape[1]
        raw = np.column_stack([np.interp(p.t, valid.t, valid.tau[:, j]) for j in range(nv)])
        d = raw - p.tau
        out[c] = (
            float(np.linalg.norm(d) / np.linalg.norm(raw)),
            (np.linalg.norm(d, axis=0) / np.linalg.norm(raw, axis=0)).tolist(),
        )
    return out


def static_basis(dq, q, edges) -> np.ndarray:
    """40 velocity-bin indicators and sin/cos of k q, k = 1..6, shape (N, 52)."""
    idx = np.clip(np.searchsorted(edges, dq) - 1, 0, len(edges) - 2)
    bins = np.zeros((dq.size, len(edges) - 1))
    bins[np.arange(dq.size), idx] = 1.0
    harm = np.column_stack([f(k * q) for k in range(1, 7) for f in (np.sin, np.cos)])
    return np.hstack([bins, harm])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True, help="the log (a Panda-format folder)")
    ap.add_argument("--auto", required=True, help="the JSON of --friction auto")
    ap.add_argument("--split", type=float, default=0.7)
    ap.add_argument("--cutoff", type=float, default=3.0, help="preprocessing cutoff [Hz]")
    ap.add_argument("--joint", type=int, default=7, help="joint (1-based) of floor 2")
    args = ap.parse_args(argv)
    doc = json.loads(Path(args.auto).read_text())
    robot = load_robot(doc["robot"])
    per = tuple(tuple(doc["joint_terms_per_joint"][j]) for j in doc["joints"])
    names = {t for keep in per for t in keep}
    order = max([int(t[1]) for t in names if t.startswith("h")] or [0])
    shapes = FrictionShapes.from_dict(doc.get("friction_shapes"))
    laws = JointTerms(harmonics=order, shapes=shapes, per_dof=per)  # per_dof: the columns
    r = robot.with_terms(laws)
    train, valid = load_dataset(args.data).split(args.split)
    for c, (total, joints) in raw_floor(valid, [args.cutoff, 20.0, 50.0]).items():
        print(f"raw torque above {c:g} Hz: {100 * total:.3f} % (per joint "
              + ", ".join(f"{100 * x:.2f}" for x in joints) + " %)")  # fmt: skip
    tr = preprocess(train, cutoff=args.cutoff)
    va = preprocess(valid, cutoff=args.cutoff)
    res = identify(r, (tr.q, tr.dq, tr.ddq, tr.tau), validation=(va.q, va.dq, va.ddq, va.tau))
    j = args.joint - 1
    e_tr = tr.tau[:, j] - res.predict(r, tr.q, tr.dq, tr.ddq)[:, j]
    e_va = va.tau[:, j] - res.predict(r, va.q, va.dq, va.ddq)[:, j]
    edges = np.quantile(tr.dq[:, j], np.linspace(0, 1, 41))
    c, *_ = np.linalg.lstsq(static_basis(tr.dq[:, j], tr.q[:, j], edges), e_tr, rcond=None)
    left = e_va - static_basis(va.dq[:, j], va.q[:, j], edges) @ c
    norm = np.linalg.norm(va.tau[:, j])
    chosen, best = 100 * np.linalg.norm(e_va) / norm, 100 * np.linalg.norm(left) / norm
    print(
        f"joint {args.joint} validation error: chosen model {chosen:.2f} %, with the best "
        f"static law of (dq, q) on its residual {best:.2f} %"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
