"""`manip-id rank`: table, JSON, --data, bad input (one line, exit 2, no partial file)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from manip_id.cli import main

M, C, K, B = 2.0, 0.8, 5.0, 1.5
ROTATIONAL = [f"cart.{p}" for p in ("mcx", "mcy", "mcz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")]


def _msd_npz(path, *, with_ddq=True, static=False):
    t = np.arange(0.0, 20.0, 0.01)

    def u_of(tt):
        return 1.2 * np.sin(1.1 * tt) + 0.7 * np.sin(2.3 * tt)

    sol = solve_ivp(
        lambda tt, x: [x[1], (B * u_of(tt) - C * x[1] - K * x[0]) / M],
        (t[0], t[-1]),
        [0.0, 0.0],
        t_eval=t,
        rtol=1e-10,
        atol=1e-12,
    )
    y, dy = sol.y
    ddy = (B * u_of(t) - C * dy - K * y) / M
    if static:  # the cart held still at distinct positions: mass never accelerated
        y = np.linspace(-0.5, 0.5, t.size)
        dy = np.zeros_like(y)
        ddy = np.zeros_like(y)
    arrays = {"t": t, "q": y[:, None], "dq": dy[:, None], "tau": (B * u_of(t))[:, None]}
    if with_ddq:
        arrays["ddq"] = ddy[:, None]
    np.savez(path, **arrays)
    return path


def test_rank_msd_table_and_json(tmp_path, capsys):
    out = tmp_path / "msd.json"
    assert main(["rank", "msd", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "rank (base params)   3" in text
    assert "never rotates" in text
    data = json.loads(out.read_text())
    for key in (
        "robot",
        "n_parameters",
        "rank",
        "condition_number",
        "base_parameters",
        "unidentifiable",
        "singular_values",
    ):
        assert key in data
    assert data["robot"] == "msd" and data["n_parameters"] == 12 and data["rank"] == 3
    assert [b["name"] for b in data["base_parameters"]] == ["cart.m", "cart.fv", "cart.k"]
    assert data["unidentifiable"] == ROTATIONAL
    assert len(data["singular_values"]) == 12


@pytest.mark.parametrize(
    ("args", "rank", "p"),
    [
        (["panda"], 43, 70),
        (["ur5", "--armature"], 40, 66),
    ],
)
def test_rank_published_counts(tmp_path, capsys, args, rank, p):
    out = tmp_path / "r.json"
    assert main(["rank", *args, "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["rank"] == rank and data["n_parameters"] == p
    assert len(data["base_parameters"]) == rank
    assert len(data["unidentifiable"]) == p - rank
    assert f"base parameters ({rank})" in capsys.readouterr().out


@pytest.mark.parametrize("with_ddq", [True, False])
def test_rank_with_data(tmp_path, capsys, with_ddq):
    data_file = _msd_npz(tmp_path / "msd.npz", with_ddq=with_ddq)
    out = tmp_path / "r.json"
    assert main(["rank", "msd", "--data", str(data_file), "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["data"]["rank"] == 3
    assert result["data"]["unexcited"] == []
    assert "msd trajectory" in capsys.readouterr().out


def test_rank_with_static_data_reports_unexcited_mass(tmp_path, capsys):
    data_file = _msd_npz(tmp_path / "still.npz", static=True)
    out = tmp_path / "r.json"
    assert main(["rank", "msd", "--data", str(data_file), "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    # dq = ddq = 0: the viscous and inertial columns vanish, only the spring is excited
    assert result["data"]["rank"] == 1
    assert sorted(result["data"]["unexcited"]) == ["cart.fv", "cart.m"]
    assert "not excited" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["rank", "no_such_robot"], "no_such_robot"),
        (["rank", "msd", "--data", "/nonexistent/data.npz"], "no such data file"),
        (["rank", "msd", "--friction", "sticky"], "unknown friction kind"),
        (["rank", "msd", "--tolerance", "3"], "tolerance"),
    ],
)
def test_bad_input_one_line_exit_2_no_partial_file(tmp_path, capsys, args, message):
    out = tmp_path / "never.json"
    assert main([*args, "--json", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("manip-id: error:") and message in err[0]
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []


def test_data_of_another_robot_is_rejected(tmp_path, capsys):
    data_file = _msd_npz(tmp_path / "msd.npz")
    assert main(["rank", "panda", "--data", str(data_file)]) == 2
    assert "nv=7" in capsys.readouterr().err
