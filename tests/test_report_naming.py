"""What reports call things: runs of many files, links, regrouped base parameters."""

from __future__ import annotations

import pinocchio as pin
import pytest
from conftest import get_robot

from manip_id.identifiability import REGROUPED_NOTE, analyze, has_regrouped
from manip_id.viz import ReportContent, write_report
from manip_id.viz.link_colors import link_names
from manip_id.viz.report_document import data_in_words


def test_a_run_of_many_files_is_named_by_its_count_and_folder_not_its_list():
    files = [f"logs/run_{k}.npz" for k in range(12)]
    assert data_in_words(files) == "12 files in logs/ (run_0.npz ... run_11.npz)"
    assert data_in_words(files[:2]) == "2 files in logs/ (run_0.npz, run_1.npz)"
    assert data_in_words(["a/x.csv", "b/y.csv"]) == "2 files (x.csv, y.csv)"
    assert data_in_words(["logs/run_0.npz@0:14.6"]) == "logs/run_0.npz@0:14.6"  # one: its path


@pytest.mark.parametrize("name", ["panda", "ur5"])
def test_bodies_are_named_by_the_link_their_joint_moves(name):
    # the URDF's child link of each joint is the BODY frame Pinocchio adds right after it
    robot = get_robot(name)
    model = robot.model
    want = []
    for j in range(1, model.njoints):
        k = next(i for i, f in enumerate(model.frames) if f.name == model.names[j])
        assert model.frames[k + 1].type == pin.BODY
        want.append(model.frames[k + 1].name)
    assert link_names(model) == want
    assert not set(want) & set(robot.joint_names)


def test_the_r_suffix_is_explained_under_a_table_that_shows_it(tmp_path):
    base = analyze(get_robot("ur5")).base
    names, expressions = base.base_names, base.expressions
    # R marks exactly the base parameters whose expression holds more than their own name
    assert [n.endswith("R") for n in names] == [
        e.strip() != n for n, e in zip(names, expressions, strict=True)
    ]
    assert has_regrouped(names)  # the ur5 has regrouped parameters
    assert not has_regrouped(get_robot("ur5").parameter_names)  # no standard name ends in R
    rows = [{"name": n, "expression": e} for n, e in zip(names, expressions, strict=True)]
    for table, explained in ((rows, True), ([r for r in rows if r["name"][-1] != "R"], False)):
        folder = write_report(
            tmp_path / str(explained),
            ReportContent(title="t", summary={}, parameter_table=table, figures={}),
        )
        page = (folder / "index.html").read_text()
        assert (REGROUPED_NOTE[1:] in page) is explained
