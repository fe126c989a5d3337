"""Robot profiles (robots/NAME.toml): defaults that explicit options override; packaging."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import tomllib

from manip_id.cli import main
from manip_id.errors import InputError, RobotError
from manip_id.robot.model import load_robot
from manip_id.robot.profiles import load_profile, parse_profile, robots_dir
from manip_id.trajectories import FourierTrajectory, random_trajectory

ROOT = Path(__file__).resolve().parents[1]
#: Franka's published maximum joint accelerations [rad/s^2] (FCI "Robot and interface
#: specifications"), typed here from the datasheet, not read from panda.toml.
PANDA_DDQ_MAX = np.array([15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0])


def test_robot_files_live_in_the_top_level_folder():
    assert robots_dir() == ROOT / "robots"
    for name in ("msd.urdf", "msd.json", "msd.toml", "panda.toml"):
        assert (ROOT / "robots" / name).is_file()
    assert not (ROOT / "manip_id" / "robots").exists()  # one copy in the tree


def test_panda_profile_locks_the_fingers_and_options_override_it():
    robot = load_robot("panda")
    assert robot.profile is not None and robot.profile.name == "panda"
    assert robot.nv == 7 and "panda_finger_joint1" not in robot.joint_names
    assert load_robot("panda", profile=False).nv == 9  # no profile: every joint
    arm = load_robot("panda", active_joints=["panda_joint1", "panda_joint2"])
    assert arm.joint_names == ["panda_joint1", "panda_joint2"]  # explicit beats the profile


def test_msd_profile_sets_its_joint_terms():
    assert load_robot("msd").terms.enabled == ("fv", "k")
    assert load_robot("msd", spring=False).terms.enabled == ("fv",)
    assert load_robot("msd", friction="coulomb").terms.enabled == ("fc", "k")
    assert load_robot("msd", profile=False).terms.enabled == ()


def test_a_urdf_by_path_does_not_depend_on_its_file_name(tmp_path):
    source = Path(load_robot("panda").source)
    for name in ("panda.urdf", "my_arm.urdf"):
        copy = tmp_path / name
        shutil.copy(source, copy)
        # the file name decides nothing: no profile locks the mimicking fingers, so the
        # URDF by path is refused (issue 41) whatever its name
        with pytest.raises(RobotError, match="'panda_finger_joint2' mimics"):
            load_robot(copy)
        assert load_robot(copy, profile="panda").nv == 7  # a profile does


def test_profile_from_a_file_and_the_cli_option(tmp_path, capsys):
    prof = tmp_path / "two.toml"
    prof.write_text(
        '[joints]\nactive = ["panda_joint1", "panda_joint2"]\n[model]\narmature = true\n'
    )
    robot = load_robot("panda", profile=prof)
    assert robot.nv == 2 and robot.terms.enabled == ("Ia",)
    for option, out in ((str(prof), "two.json"), ("none", "none.json")):
        args = ["rank", "panda", "--profile", option, "--json", str(tmp_path / out)]
        assert main(args) == 0
    capsys.readouterr()
    import json

    two = json.loads((tmp_path / "two.json").read_text())
    full = json.loads((tmp_path / "none.json").read_text())
    assert two["n_parameters"] == 2 * 10 + 2  # two bodies and their armatures
    assert full["n_parameters"] == 9 * 10  # no profile: the fingers move too


def test_excitation_profile_keeps_panda_within_its_datasheet_accelerations():
    robot = load_robot("panda")
    design = robot.profile.excitation.design_kwargs()
    assert design["harmonics"] == 5 and design["wf"] == pytest.approx(2 * np.pi / 10.0)
    traj = random_trajectory(robot, seed=3, **design)
    t = np.linspace(0.0, traj.period, 4001)
    # accelerations of the Fourier series evaluated here from its coefficients alone
    L = traj.a.shape[1]
    w = traj.wf * np.arange(1, L + 1)
    ddq = -np.sin(np.outer(t, w)) @ (traj.a * w).T + np.cos(np.outer(t, w)) @ (traj.b * w).T
    assert isinstance(traj, FourierTrajectory)
    assert np.all(np.abs(ddq).max(axis=0) <= PANDA_DDQ_MAX * (1 + 1e-9))


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[model]\nfriction = ['sticky']\n", "model.friction holds 'sticky'"),
        ("[model]\nspring = 'yes'\n", "spring must be true or false"),
        ("[joints]\nactive = ['a']\nlocked = ['b']\n", "not both"),
        ("[excitation]\nharmonics = 2.5\n", "harmonics must be a positive integer"),
        ("[excitation]\nmargin = 0.7\n", r"margin must be in \[0, 0.5\)"),
        ("[data]\ntorque_scale = [1.0, 0.0]\n", r"torque_scale\[1\] must be non-zero"),
        ("[exitation]\nharmonics = 5\n", "unknown key 'exitation'"),
        ("[model]\nfrictions = []\n", "unknown key model.'frictions'"),
    ],
)
def test_bad_profiles_name_the_file_and_the_key(tmp_path, text, match):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=match) as info:
        load_profile(path)
    assert str(path) in str(info.value)


def test_unknown_or_unreadable_profiles():
    with pytest.raises(RobotError, match="no nosuchrobot.toml"):
        load_profile("nosuchrobot")
    with pytest.raises(InputError, match="unknown joint 'no_joint'"):
        load_robot("ur5", profile=parse_profile({"joints": {"active": ["no_joint"]}}, name="x"))


def test_pyproject_installs_every_package_and_the_robot_files():
    """The explicit package list matches the tree; robots/ is installed as manip_id.robots."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    tree = {
        ".".join(p.parent.relative_to(ROOT).parts)
        for p in (ROOT / "manip_id").rglob("__init__.py")
        if "__pycache__" not in p.parts
    }
    assert set(config["packages"]) == tree | {"manip_id.robots"}
    assert config["package-dir"] == {"manip_id.robots": "robots"}
    patterns = config["package-data"]["manip_id.robots"]
    shipped = {p.name for pat in patterns for p in (ROOT / "robots").glob(pat)}
    assert {"msd.urdf", "msd.json", "msd.toml", "panda.toml"} <= shipped
