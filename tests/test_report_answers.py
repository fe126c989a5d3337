"""The questions an identification report answers first (manip_id.viz.report_answers),
the readable tables (manip_id.viz.report_tables) and the consistent report end to end."""

from __future__ import annotations

import html
import json

import numpy as np
import pinocchio as pin
import pytest
from conftest import get_robot

from manip_id.cli import main
from manip_id.viz.report_answers import body_rows, identify_answers, next_steps, trust
from manip_id.viz.report_tables import number, report_parameter_rows, report_quality_rows


def _body_doc(name: str, inertia: pin.Inertia, nominal: pin.Inertia) -> dict:
    kinds = ("m", "mcx", "mcy", "mcz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
    values, nominals = inertia.toDynamicParameters(), nominal.toDynamicParameters()
    return {
        "standard_parameters": [
            {"name": f"{name}.{k}", "value": float(v), "nominal": float(n), "unit": ""}
            for k, v, n in zip(kinds, values, nominals, strict=True)
        ]
    }


def test_body_rows_recover_mass_centre_and_moments_of_a_pinocchio_inertia():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(3, 3))
    I_c = a @ a.T + 0.1 * np.eye(3)  # [kg m^2] about the centre of mass
    c = np.array([0.12, -0.05, 0.31])  # [m]
    ident = pin.Inertia(2.5, c, I_c)
    nominal = pin.Inertia(1.0, np.zeros(3), np.eye(3))
    (row,) = body_rows(_body_doc("link", ident, nominal))
    assert row["mass [kg]"] == number(2.5) and row["mass ratio"] == number(2.5, 3)
    assert row["centre of mass [m]"] == "(" + ", ".join(number(x, 3) for x in c) + ")"
    moments = np.sort(np.linalg.eigvalsh(I_c))
    assert (
        row["moments about the CoM [kg m^2]"]
        == "(" + ", ".join(number(x, 3) for x in moments) + ")"
    )
    assert row["plausibility"] == "ok"
    (far,) = body_rows(_body_doc("link", pin.Inertia(4.0, c, I_c), nominal))
    assert "4 x nominal" in far["plausibility"] and far["_class"] == "bad"


def test_a_parameter_beyond_1000_percent_reads_not_determined():
    base = {"unit": "kg", "nominal": 1.0, "expression": "x", "flags": []}
    doc = {
        "base_parameters": [
            {**base, "name": "a", "value": -9.613e16, "std": 4.2e18, "std_percent": 4.35e9},
            {**base, "name": "b", "value": 2.0, "std": 0.1, "std_percent": 5.0},
        ]
    }
    rows = {r["name"]: r for r in report_parameter_rows(doc)}
    assert rows["a"]["identified"] == "not determined" and rows["a"]["std [%]"] == "-"
    assert "not determined by these data" in rows["a"]["flags"]
    assert rows["b"]["identified"] == "2" and rows["b"]["std [%]"] == "5"
    text = json.dumps(rows)
    assert "e+16" not in text and "e+09" not in text


def test_quality_rows_have_names_and_units():
    q = {"file": "f.csv", "n_samples": 10, "n_dropped": 2, "first_dropped": 3, "jitter": 0.1776}
    q |= {"dt_min": 0.0007, "dt_max": 0.00881, "standstill_eps": 0.01, "warnings": []}
    q |= {"standstill_share": {"j1": 0.01, "j2": 0.03}, "rate": 984.28, "duration": 14.6}
    (row,) = report_quality_rows({"data_quality": [q]})
    assert row["jitter [%]"] == "18" and row["rows dropped"] == 2
    assert row["first dropped row"] == 3
    assert row["shortest step [ms]"] == "0.7" and row["longest step [ms]"] == "8.81"
    assert row["standstill (|dq| < 0.01 rad/s) [%]"] == "1 - 3"
    assert not {"n_dropped", "first_dropped", "dt_min", "standstill_eps", "jitter"} & set(row)


def test_next_steps_give_the_option_that_fixes_a_warning():
    _, html = next_steps(["non-physical values: j.m = -1 kg"])
    assert "--consistent" in html and html.count("<li>") == 1
    assert "Nothing to fix" in next_steps([])[1]


@pytest.fixture(scope="module")
def consistent_report(tmp_path_factory):
    work = tmp_path_factory.mktemp("consistent")
    argv = ["identify", "double_pendulum", "--simulate", "--consistent", "--split", "0.7"]
    argv += ["--export-urdf", str(work / "id.urdf"), "--report", str(work / "rep")]
    assert main(argv) == 0
    return work


def test_consistent_report_answers_first(consistent_report):
    page = (consistent_report / "rep" / "index.html").read_text()
    doc = json.loads((consistent_report / "rep" / "result.json").read_text())
    heads = ["How good is the model?", "Can I trust the numbers?", "Is it physical?"]
    heads += ["What was exported?", "What to do next?"]
    at = [page.index(h) for h in heads]
    assert at == sorted(at) and at[-1] < page.index("<h2>Summary</h2>")
    assert 'Physically consistent: <span class="yes">yes</span>' in page
    assert 'href="../id.urdf"' in page and "id.identified.json" in page
    masses = {p["name"]: p["value"] for p in doc["standard_parameters"] if p["name"].endswith(".m")}
    for name, m in masses.items():
        assert f"<td>{name.rsplit('.', 1)[0]}</td><td>{number(m)}</td>" in page
    for w in doc["warnings"]:
        assert html.escape(w[1:40]) in page  # each warning, as a sentence


def test_plain_least_squares_says_it_did_not_check(tmp_path):
    robot = get_robot("double_pendulum")
    doc = {
        "relative_error": {"train": 0.01, "validation": None, "train_per_joint": [0.01, 0.02]},
        "joints": robot.dof_names,
        "base_parameters": [],
        "condition_number": 12.0,
    }
    answers = dict(identify_answers(doc))
    assert "Not checked" in answers["Is it physical?"]
    assert "--consistent" in answers["Is it physical?"]
    assert "training data" in answers["How good is the model?"]


@pytest.mark.parametrize("method", ["hac", "white"])
def test_trust_gives_one_std_figure_for_correlated_residuals(method):
    """A chi-square 272 times its expectation: with autocorrelation-consistent std the
    answer names their inflation (what the tables show), not also sqrt(272) = 16."""
    doc = {
        "base_parameters": [],
        "condition_number": 96.0,
        "consistent_solver": {"fit_scale": 272.0},
        "uncertainty": {"method": method, "inflation": 14.8 if method == "hac" else None},
    }
    head, body = trust(doc)
    assert head == "Can I trust the numbers?"
    assert "272 times its expected chi-square" in body
    if method == "hac":
        assert "14.8 times the white-noise ones" in body and "16 times" not in body
        assert body.count("standard deviations") == 1
    else:
        assert "about 16 times too small" in body
