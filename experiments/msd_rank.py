"""The mass-spring-damper as a one-DoF special case of rank analysis: two views.

    m y'' + c y' + k y = b u,   m = 2 kg, c = 0.8 N s/m, k = 5 N/m, b = 1.5,
    u(t) = 1.2 sin(1.1 t) + 0.7 sin(2.3 t),   y(0) = y'(0) = 0.

View 1, the Pinocchio model ``"msd"`` (a cart on a prismatic joint, viscous and
spring terms), torque ``tau = b u`` with b known: of the cart's 10 rigid-body
parameters only the mass enters (a prismatic joint never rotates its body);
m, c and k are identifiable and least squares recovers them.

View 2, the textbook model with b unknown: ``[y'', y', y, -u] rho = 0`` with
``rho = [m, c, k, b]`` is homogeneous; its columns have rank 3 of 4 and the
null space is the line through rho: only ratios are identifiable. The
control-oriented form ``y'' = phi^T theta``, ``phi = [-y, -y', u]``,
``theta = [k/m, c/m, b/m]`` is full rank.

Run: ``.venv/bin/python experiments/msd_rank.py``
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from manip_id import load_robot
from manip_id.identifiability import analyze, analyze_trajectory
from manip_id.robot.regressor import regressor

M, C, K, B = 2.0, 0.8, 5.0, 1.5


def u_of(t):
    """Input u(t) of the textbook example."""
    return 1.2 * np.sin(1.1 * t) + 0.7 * np.sin(2.3 * t)


def simulate(duration: float = 30.0, rate: float = 50.0):
    """(t, y, y', y'', u) of the msd from rest, y'' from the equation of motion."""
    t = np.arange(0.0, duration, 1.0 / rate)

    def f(tt, x):
        return [x[1], (B * u_of(tt) - C * x[1] - K * x[0]) / M]

    sol = solve_ivp(f, (t[0], t[-1]), [0.0, 0.0], t_eval=t, rtol=1e-11, atol=1e-12, method="DOP853")
    y, dy = sol.y
    u = u_of(t)
    ddy = (B * u - C * dy - K * y) / M
    return t, y, dy, ddy, u


def main() -> None:
    t, y, dy, ddy, u = simulate()
    print("=== view 1: the Pinocchio model 'msd', tau = b u with b known ===")
    robot = load_robot("msd")
    b = robot.settings["input_gain"]
    data = analyze_trajectory(robot, y[:, None], dy[:, None], ddy[:, None])
    print(data.report())
    Y = regressor(robot, y[:, None], dy[:, None], ddy[:, None]).reshape(-1, robot.n_parameters)
    tau = b * u
    theta_b = np.linalg.lstsq(data.base.regressor(Y), tau, rcond=None)[0]
    print("\nleast squares on the base regressor, tau = b u:")
    for name, value, true in zip(data.base.base_names, theta_b, (M, C, K), strict=True):
        print(f"  {name:8s} = {value:.6f}   (true {true})")

    print("\n=== view 2: the textbook model, b unknown: columns [y'', y', y, -u] ===")
    homog = analyze(np.column_stack([ddy, dy, y, -u]), names=["m", "c", "k", "b"])
    print(homog.report())
    rho = np.array([M, C, K, B])
    n = homog.null_space[:, 0]
    cos = abs(n @ rho) / (np.linalg.norm(n) * np.linalg.norm(rho))
    print(
        f"\nnull direction scaled to b = 1.5: {np.round(n / n[3] * B, 6).tolist()}"
        f"   rho = {rho.tolist()}   |cos angle| = {cos:.12f}"
    )

    print(
        "the regression is homogeneous: any multiple of rho fits the data as well, so the data\n"
        "fix rho only up to scale and only ratios (k/m, c/m, b/m) are identifiable"
    )

    print("\n=== control-oriented form y'' = phi^T theta, phi = [-y, -y', u] ===")
    phi = np.column_stack([-y, -dy, u])
    ctrl = analyze(phi, names=["k/m", "c/m", "b/m"])
    print(
        f"rank {ctrl.rank} of {ctrl.n_parameters}, condition number "
        f"{ctrl.condition_number:.4g}, unidentifiable: {ctrl.unidentifiable or 'none'}"
    )
    theta = np.linalg.lstsq(phi, ddy, rcond=None)[0]
    print(
        f"least squares theta = {np.round(theta, 6).tolist()}   "
        f"true [k/m, c/m, b/m] = {[K / M, C / M, B / M]}"
    )

    print("\n=== textbook: rows [1, 0], [2, 0], [3, 0] ===")
    small = analyze([[1.0, 0.0], [2.0, 0.0], [3.0, 0.0]], names=["theta1", "theta2"])
    print(f"rank {small.rank} of 2, unidentifiable direction: {small.unidentifiable}")


if __name__ == "__main__":
    main()
