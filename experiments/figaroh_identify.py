"""FIGAROH's identification of one record (run by bench_figaroh.py in FIGAROH's environment).

    $FIGAROH_PYTHON experiments/figaroh_identify.py DATA.npz URDF PACKAGE_DIR OUT.json

Imports FIGAROH (1.0.2) and nothing of manip_id. The steps are those of
FIGAROH's ``BaseIdentification.solve`` without decimation, plotting or
files, through its public functions: the robot from the URDF
(``figaroh.tools.robot.Robot``), the regressor with viscous and Coulomb
("static") friction (``build_regressor_basic``), the standard parameters,
elimination of unexcited columns (``get_index_eliminate``,
``build_regressor_reduced``), base parameters and their least-squares
estimate by the double QR (``QRDecomposer.double_decomposition``) and the
relative standard deviations (``relative_stdev``). Writes the base parameter
count, the relative torque error and the time of each step as JSON.
"""

from __future__ import annotations

import json
import sys
import time


def main(argv: list[str]) -> int:
    data_path, urdf, package_dir, out_path = argv
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    import numpy as np
    from figaroh.identification.identification_tools import relative_stdev
    from figaroh.identification.parameter import (
        add_standard_additional_parameters,
        get_standard_parameters,
    )
    from figaroh.tools.qrdecomposition import QRDecomposer
    from figaroh.tools.regressor import (
        build_regressor_basic,
        build_regressor_reduced,
        get_index_eliminate,
    )
    from figaroh.tools.robot import Robot

    timings["imports"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    robot = Robot(urdf, package_dir)
    model = robot.model
    timings["robot"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    with np.load(data_path) as f:
        q, dq, ddq, tau = (np.asarray(f[k]) for k in ("q", "dq", "ddq", "tau"))
    n, nv = tau.shape
    timings["load"] = time.perf_counter() - t0

    config = {
        "has_friction": True,
        "has_actuator_inertia": False,
        "has_joint_offset": False,
        "is_joint_torques": True,
        "is_external_wrench": False,
        "act_idxv": list(range(nv)),
        "fv": [0.0] * nv,
        "fs": [0.0] * nv,
    }
    t0 = time.perf_counter()
    W = build_regressor_basic(robot, q, dq, ddq, config)
    timings["regressor"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    params_std = get_standard_parameters(model, config)
    params_std.update(add_standard_additional_parameters(model, config))
    idx_e, params_r = get_index_eliminate(W, params_std, tol_e=0.001)
    W_e = build_regressor_reduced(W, idx_e)
    tau_stacked = tau.T.reshape(-1)  # FIGAROH stacks joint-major: row j * N + k
    decomposer = QRDecomposer(tolerance=1e-6)
    W_b, _, params_base, phi_b, _ = decomposer.double_decomposition(
        tau_stacked, W_e, params_r, params_std
    )
    std_percent = relative_stdev(W_b, np.asarray(phi_b), tau_stacked)
    timings["base_and_solve"] = time.perf_counter() - t0

    residual = tau_stacked - W_b @ phi_b
    rel = float(np.linalg.norm(residual) / np.linalg.norm(tau_stacked))
    timings["total"] = time.perf_counter() - t_start
    out = {
        "n_samples": int(n),
        "n_base": len(params_base),
        "relative_error": rel,
        "max_std_percent": float(np.max(std_percent)),
        "timings": timings,
    }
    with open(out_path, "w") as f:
        json.dump(out, f)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
