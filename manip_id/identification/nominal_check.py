"""The identified model against the nominal one, joint by joint: a warning a user can act on.

A fit that predicts a joint's torques worse than the nominal (URDF) parameters do, by more
than ``WORSE_RATIO`` times and ``WORSE_MARGIN`` of relative error, has made that joint
worse; the warning names the joints with both errors and says what to do (a plain OLS fit
lets the loud joints' noise set the parameters a quiet joint depends on: weight the joints,
``method="wls"``). The errors are those of :class:`RelativeError`: ``||tau_j - tau_hat_j||
/ ||tau_j||`` per joint on the validation data when there are some, else on training data.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

#: A joint counts as made worse when its error exceeds the nominal model's by this factor ...
WORSE_RATIO = 1.2
#: ... and by this much relative torque error (0.2 %) [1].
WORSE_MARGIN = 0.002
#: Every warning of this check starts so (the JSON reader recomputes them).
WORSE_PREFIX = "worse than the nominal model on "


def worse_than_nominal(
    method: str,
    joints: Sequence[str],
    errors,
    nominal,
    part: str = "validation",
) -> str | None:
    """The warning for the joints whose error is worse than the nominal model's, else None.

    ``errors`` and ``nominal``: per-joint relative torque errors [1], shape (nv,), of the
    identified and the nominal model on the same data (``part``: "validation" or
    "training"); a None or NaN entry is skipped.
    """
    if errors is None or nominal is None:
        return None
    e = np.array([np.nan if x is None else x for x in errors], dtype=float)
    n = np.array([np.nan if x is None else x for x in nominal], dtype=float)
    if e.shape != n.shape or e.shape != (len(joints),):
        return None
    with np.errstate(invalid="ignore"):
        worse = (e > WORSE_RATIO * n) & (e - n > WORSE_MARGIN)
    if not worse.any():
        return None
    listed = ", ".join(
        f"{j} {100 * e[i]:.3f} % (nominal {100 * n[i]:.3f} %)"
        for i, j in enumerate(joints)
        if worse[i]
    )
    if method == "ols":
        do = (
            "refit with --method wls (Python: method='wls'): plain OLS lets the loud joints' "
            "noise set the parameters a quiet joint depends on; else keep the nominal model"
        )
    else:
        do = (
            "excite these joints more (longer or richer motion), check their friction and "
            "armature terms (--friction, --armature), or keep the nominal model for them"
        )
    return f"{WORSE_PREFIX}the {part} data: {listed}. Do: {do}"


def result_worse_than_nominal(result) -> str | None:
    """:func:`worse_than_nominal` of an identification result (validation errors when
    known, else training errors; torque outputs only)."""
    re = result.relative_error
    joints = list(result.dof_names or [])
    if re.validation_per_joint is not None:
        return worse_than_nominal(
            result.method, joints, re.validation_per_joint, re.nominal_validation_per_joint
        )
    if getattr(result, "model", "dynamic") != "dynamic":
        return None
    return worse_than_nominal(
        result.method, joints, re.train_per_joint, re.nominal_train_per_joint, "training"
    )


__all__ = ["WORSE_MARGIN", "WORSE_PREFIX", "WORSE_RATIO", "result_worse_than_nominal"]
