"""Start-up stays light: what ``import manip_id`` and ``manip-id --help`` load.

Each check runs a fresh interpreter and reads its ``sys.modules``; nothing is timed.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

import manip_id

#: Modules a command must import only when it uses them.
HEAVY = (
    "matplotlib",
    "meshcat",
    "scipy.signal",
    "scipy.optimize",
    "scipy.stats",
    "cvxpy",
    "rosbags",
    "dask",
)


def _modules_after(code: str) -> set[str]:
    """The names in ``sys.modules`` after a fresh interpreter runs ``code``."""
    script = f"import json, sys\n{code}\nprint('\\n' + json.dumps(sorted(sys.modules)))\n"
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", MPLBACKEND="Agg")
    out = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
        check=True,
    )
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def _heavy(modules: set[str]) -> list[str]:
    return sorted(m for m in modules if any(m == h or m.startswith(h + ".") for h in HEAVY))


def _cli(argv: list[str]) -> str:
    """Code that runs ``manip-id ARGV`` as the console script does, keeping the process alive."""
    return (
        f"from manip_id.cli import main\ntry:\n    main({argv!r})\nexcept SystemExit:\n    pass\n"
    )


def test_import_loads_no_submodule():
    mods = _modules_after("import manip_id")
    assert _heavy(mods) == []
    assert "pinocchio" not in mods
    assert sorted(m for m in mods if m.startswith("manip_id")) == ["manip_id"]


@pytest.mark.parametrize(
    "argv",
    [["--help"], ["identify", "--help"], ["rank", "--help"], ["adapt", "--help"], ["robots", "-h"]],
)
def test_help_imports_nothing_heavy(argv):
    mods = _modules_after(_cli(argv))
    assert "manip_id.cli.identify" in mods  # the parser was really built
    assert _heavy(mods) == []
    assert "pinocchio" not in mods


def test_subpackages_import_lazily():
    mods = _modules_after("import manip_id.viz, manip_id.estimators")
    assert _heavy(mods) == []
    assert "scipy.linalg" not in mods


def test_one_name_loads_only_what_it_needs():
    mods = _modules_after("from manip_id import InputError, Dataset")
    assert "pinocchio" not in mods
    assert _heavy(mods) == []


def test_every_exported_name_resolves():
    for name in manip_id.__all__:
        assert getattr(manip_id, name) is not None, name
    assert set(manip_id.__all__) <= set(dir(manip_id))
    assert len(set(manip_id.__all__)) == len(manip_id.__all__)
    with pytest.raises(AttributeError, match="no_such_name"):
        manip_id.no_such_name  # noqa: B018


def test_exports_are_the_submodules_objects():
    from manip_id import identification, simulation
    from manip_id.control import closed_loop
    from manip_id.estimators import batch

    assert manip_id.identify is identification.identify
    assert manip_id.simulate is simulation.simulate
    assert manip_id.simulate_adaptive is closed_loop.simulate
    assert manip_id.solve_stacked is batch.solve_stacked


def test_export_named_like_its_submodule_stays_the_function():
    import manip_id.robot.regressor  # noqa: F401 (imports the submodule of the same name)
    from manip_id import regressor
    from manip_id.robot.regressor import regressor as function

    assert regressor is function
    assert callable(regressor) and not isinstance(regressor, type(manip_id))
    assert sys.modules["manip_id.robot.regressor"].regressor is function


def test_subpackage_exports_resolve():
    import manip_id.estimators as est
    import manip_id.viz as viz

    for mod in (est, viz):
        for name in mod.__all__:
            assert getattr(mod, name) is not None, (mod.__name__, name)
    assert viz.figures is sys.modules["manip_id.viz.figures"]


def test_robots_command_imports_nothing_heavy():
    mods = _modules_after(_cli(["robots"]))
    assert "pinocchio" in mods  # it really built the models
    assert _heavy(mods) == []


def _reference_configurations(model) -> dict:
    return {e.key(): tuple(e.data()) for e in model.referenceConfigurations}


@pytest.mark.parametrize("name", ["panda", "ur10", "talos_arm", "baxter"])
def test_model_without_geometry_matches_the_loader(name):
    """The URDF-only model equals the one example-robot-data's loader builds (with meshes)."""
    import numpy as np
    from example_robot_data.robots_loader import ROBOTS

    from manip_id.robot.model import load_robot
    from manip_id.robot.sources import load_erd

    ref = ROBOTS[name]().robot
    model, source, _, geometry = load_erd(name)
    assert geometry == {}
    assert source == ref.urdf or source.endswith(ref.urdf.split("/robots/")[-1])
    r = ref.model
    assert list(model.names) == list(r.names)
    for i in range(model.njoints):
        np.testing.assert_array_equal(
            model.inertias[i].toDynamicParameters(), r.inertias[i].toDynamicParameters()
        )
        assert model.jointPlacements[i].isApprox(r.jointPlacements[i], 0.0)
    for attr in ("lowerPositionLimit", "upperPositionLimit", "velocityLimit", "effortLimit"):
        np.testing.assert_array_equal(getattr(model, attr), getattr(r, attr))
    for attr in ("armature", "rotorInertia", "rotorGearRatio", "gravity"):
        np.testing.assert_array_equal(
            np.asarray(getattr(model, attr)), np.asarray(getattr(r, attr))
        )
    assert _reference_configurations(model) == _reference_configurations(r)

    robot = load_robot(name)
    assert "visual_model" not in vars(robot)  # geometry only on demand
    reduced = r
    if robot.model.njoints != r.njoints:  # locked joints (the panda's fingers)
        import pinocchio as pin

        ids = [r.getJointId(j) for j in r.names[1:] if j not in robot.joint_names]
        reduced, (visual, collision) = pin.buildReducedModel(
            r, [ref.visual_model, ref.collision_model], ids, robot._qref
        )
    else:
        visual, collision = ref.visual_model, ref.collision_model
    assert reduced.nv == robot.nv
    for ours, theirs in ((robot.visual_model, visual), (robot.collision_model, collision)):
        assert [g.name for g in ours.geometryObjects] == [g.name for g in theirs.geometryObjects]
        for a, b in zip(ours.geometryObjects, theirs.geometryObjects, strict=True):
            assert a.parentJoint == b.parentJoint
            assert a.placement.isApprox(b.placement)
            assert os.path.realpath(a.meshPath) == os.path.realpath(b.meshPath)
