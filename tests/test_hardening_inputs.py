"""The hardening catalogue, third round (issue 29, rules 1, 2 and 5): every file read through
one checked door, every JSON / TOML input validated before use, user numbers physical.

Each CLI case runs ``manip-id`` in-process in the working folder of
:func:`test_hardening.work` and asserts exit status 2, exactly one stderr line
``manip-id...: error: ...`` matching the case, no traceback, every input byte-identical
and nothing left behind. The properties feed random JSON / TOML structures to every
reader and assert that only :class:`~manip_id.errors.ManipIdError` comes out.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from _catalogue import arm_urdf, error_lines, snapshot, write_npz
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_hardening import work  # noqa: F401 (work: fixture)

from manip_id.cli import main
from manip_id.errors import ManipIdError

SIDECAR = {
    "format": "manip_id identified parameters",
    "version": 2,
    "joints": {"j1": {"Ia": 0.1, "fv": 0.2}, "j2": {}},
    "active_joints": ["j1", "j2"],
    "joint_terms": ["Ia", "fv"],
}
GAINS = {
    "command": "drive-gains",
    "robot": "msd",
    "joints": ["cart"],
    "drive_gains": [{"joint": "cart", "gain": 1.5, "std": 0.01, "determined": True}],
}
IDENTIFY = ["identify", "msd", "--data", "log.npz"]
SCALE = [*IDENTIFY, "--torque-scale-from", "ts.json"]
KNOWN = ["payload", "msd", "--known-base", "kb.json", "--loaded", "log.npz", "--frame", "cart"]
MONITOR = ["monitor", "arm.urdf", "--identified", "--data", "log.npz", "--calibrate", "log.npz"]
GAINS_CMD = ["drive-gains", "msd", "--unloaded", "log.npz", "--loaded", "valid.npz"]
GAINS_CMD += ["--frame", "cart"]


@pytest.fixture(scope="module")
def result_doc(tmp_path_factory) -> dict:
    """A real ``manip-id identify --json`` document of the msd (tampered by the cases)."""

    folder = tmp_path_factory.mktemp("result")
    write_npz(folder / "log.npz")
    out = folder / "r.json"
    assert main(["identify", "msd", "--data", str(folder / "log.npz"), "--json", str(out)]) == 0
    return json.loads(out.read_text())


def _clear(path: Path) -> Path:
    """``path`` free for a case's own file (the default inputs are regular files)."""
    if os.path.lexists(path):
        path.unlink()
    return path


def _write(name: str, doc) -> Callable[[Path, dict], None]:
    def setup(w: Path, result: dict) -> None:
        _clear(w / name)
        value = doc(result) if callable(doc) else doc
        text = value if isinstance(value, str | bytes) else json.dumps(value)
        if isinstance(text, bytes):
            (w / name).write_bytes(text)
        else:
            (w / name).write_text(text)

    return setup


def _fifo(name: str) -> Callable[[Path, dict], None]:
    return lambda w, result: os.mkfifo(_clear(w / name))


def _folder(name: str) -> Callable[[Path, dict], None]:
    return lambda w, result: _clear(w / name).mkdir()


def _sparse(name: str, size: int) -> Callable[[Path, dict], None]:
    def setup(w: Path, result: dict) -> None:
        with open(_clear(w / name), "wb") as fh:
            fh.truncate(size)

    return setup


def _link(name: str, target: str) -> Callable[[Path, dict], None]:
    return lambda w, result: os.symlink(target, _clear(w / name))


def _tampered(**changes):
    """The real result with keys replaced."""
    return lambda r: {**r, **changes}


def _gains(**row):
    return {**GAINS, "drive_gains": [{**GAINS["drive_gains"][0], **row}]}


def _sidecar(**changes):
    return {**SIDECAR, **changes}


def _known(**changes):
    def make(r):
        doc = {**r, **changes}
        return doc

    return make


def _urdf(old: str, new: str, name: str = "bad.urdf") -> Callable[[Path, dict], None]:
    def setup(w: Path, result: dict) -> None:
        text = arm_urdf(w / "base_arm.urdf").read_text()
        (w / "base_arm.urdf").unlink()
        assert old in text
        (w / name).write_text(text.replace(old, new, 1))

    return setup


def _two_parents(w: Path, result: dict) -> None:
    text = arm_urdf(w / "base_arm.urdf").read_text()
    (w / "base_arm.urdf").unlink()
    extra = (
        '  <joint name="j3" type="revolute"><parent link="base"/><child link="l2"/>\n'
        '    <axis xyz="1 0 0"/><limit lower="-1" upper="1" velocity="5" effort="5"/></joint>\n'
    )
    (w / "bad.urdf").write_text(text.replace("</robot>", extra + "</robot>"))


def _both(*setups):
    def setup(w: Path, result: dict) -> None:
        for s in setups:
            s(w, result)

    return setup


@dataclass
class Case:
    id: str
    argv: list[str]
    setup: Callable[[Path, dict], None] | None
    match: str


DEEP = "[" * 100_000 + "]" * 100_000
NOT_UTF8 = b'{"robot": "\xff\xfe"}'

# ------------------------------------------------------------------ rule 1: the door
DOOR = [
    Case("torque-scale-fifo", SCALE, _fifo("ts.json"), r"ts\.json is a FIFO"),
    Case("torque-scale-folder", SCALE, _folder("ts.json"), r"is a directory"),
    Case("torque-scale-dev-zero", [*IDENTIFY, "--torque-scale-from", "/dev/zero"], None, "device"),
    Case("torque-scale-dev-null", [*IDENTIFY, "--torque-scale-from", "/dev/null"], None, "device"),
    Case("torque-scale-link-to-device", SCALE, _link("ts.json", "/dev/zero"), "device"),
    Case("torque-scale-over-budget", SCALE, _sparse("ts.json", 65 << 20), r"more than the \d+"),
    Case("torque-scale-not-utf8", SCALE, _write("ts.json", NOT_UTF8), "not UTF-8"),
    Case("torque-scale-syntax", SCALE, _write("ts.json", '{"drive_gains": ['), "as JSON"),
    Case("torque-scale-deep", SCALE, _write("ts.json", DEEP), "nests deeper"),
    Case("torque-scale-missing", SCALE, None, "no such drive-gain result file"),
    Case("known-base-fifo", KNOWN, _fifo("kb.json"), "FIFO"),
    Case("known-base-folder", KNOWN, _folder("kb.json"), "directory"),
    Case("known-base-dev-zero", [*KNOWN[:3], "/dev/zero", *KNOWN[4:]], None, "device"),
    Case(
        "known-base-deep-object",
        KNOWN,
        _write("kb.json", '{"a":' * 5000 + "1" + "}" * 5000),
        "nests deeper",
    ),
    Case("show-fifo", ["show", "r.json"], _fifo("r.json"), "FIFO"),
    Case("show-dev-zero", ["show", "/dev/zero"], None, "device"),
    Case(
        "show-folder-result-fifo",
        ["show", "rep"],
        _both(_folder("rep"), _fifo("rep/result.json")),
        "FIFO",
    ),
    Case("show-not-utf8", ["show", "r.json"], _write("r.json", NOT_UTF8), "not UTF-8"),
    Case("show-deep", ["show", "r.json"], _write("r.json", DEEP), "nests deeper"),
    Case(
        "show-33-levels", ["show", "r.json"], _write("r.json", "[" * 33 + "]" * 33), "nests deeper"
    ),
    Case("show-over-budget", ["show", "r.json"], _sparse("r.json", 65 << 20), "more than"),
    Case("urdf-fifo", ["rank", "fifo.urdf", "--samples", "20"], _fifo("fifo.urdf"), "FIFO"),
    Case("urdf-folder", ["rank", "d.urdf", "--samples", "20"], _folder("d.urdf"), "directory"),
    Case("urdf-dev-null", ["rank", "/dev/null", "--samples", "20"], None, "device"),
    Case(
        "urdf-not-utf8",
        ["rank", "bad.urdf", "--samples", "20"],
        _write("bad.urdf", b"<robot name='\xff'/>"),
        "not UTF-8",
    ),
    Case("data-fifo", ["identify", "msd", "--data", "p.npz"], _fifo("p.npz"), "FIFO"),
    Case("data-dev-zero", ["identify", "msd", "--data", "/dev/zero"], None, "device"),
    Case(
        "profile-fifo",
        ["rank", "msd", "--profile", "p.toml", "--samples", "20"],
        _fifo("p.toml"),
        "FIFO",
    ),
    Case(
        "profile-not-utf8",
        ["rank", "msd", "--profile", "p.toml", "--samples", "20"],
        _write("p.toml", b'description = "\xff"'),
        "not UTF-8",
    ),
    Case(
        "profile-syntax",
        ["rank", "msd", "--profile", "p.toml", "--samples", "20"],
        _write("p.toml", "[model\nfriction = "),
        "as TOML",
    ),
    Case(
        "profile-deep",
        ["rank", "msd", "--profile", "p.toml", "--samples", "20"],
        _write("p.toml", "x = " + "[" * 40 + "]" * 40),
        "nests deeper",
    ),
    Case("sidecar-fifo", MONITOR, _fifo("arm.identified.json"), "FIFO"),
    Case("sidecar-not-utf8", MONITOR, _write("arm.identified.json", NOT_UTF8), "not UTF-8"),
    Case(
        "thresholds-fifo",
        [*MONITOR[:-2], "--thresholds", "t.json"],
        _both(_write("arm.identified.json", SIDECAR), _fifo("t.json")),
        "FIFO",
    ),
]

# ------------------------------------------------------- rule 2: JSON validated before use
SCHEMA = [
    Case(
        "known-base-covariance-strings",
        KNOWN,
        _write("kb.json", _known(covariance=[["a", "b", "c"]] * 3)),
        "covariance",
    ),
    Case(
        "known-base-covariance-object",
        KNOWN,
        _write("kb.json", _known(covariance={})),
        "covariance must be a list",
    ),
    Case(
        "known-base-covariance-shape",
        KNOWN,
        _write("kb.json", _known(covariance=[[1.0]])),
        "3 x 3 matrix",
    ),
    Case(
        "known-base-covariance-asymmetric",
        KNOWN,
        _write("kb.json", _known(covariance=[[1, 2, 0], [0, 1, 0], [0, 0, 1]])),
        "not symmetric",
    ),
    Case(
        "known-base-covariance-bool",
        KNOWN,
        _write("kb.json", _known(covariance=[[True, 0, 0], [0, 1, 0], [0, 0, 1]])),
        "finite number",
    ),
    Case(
        "known-base-value-string",
        KNOWN,
        _write(
            "kb.json",
            lambda r: {
                **r,
                "base_parameters": [
                    {**r["base_parameters"][0], "value": "abc"},
                    *r["base_parameters"][1:],
                ],
            },
        ),
        "value must be a finite number",
    ),
    Case(
        "known-base-std-negative",
        KNOWN,
        _write(
            "kb.json",
            lambda r: {
                **r,
                "base_parameters": [
                    {**r["base_parameters"][0], "std": -1.0},
                    *r["base_parameters"][1:],
                ],
            },
        ),
        "std must be a number >= 0",
    ),
    Case(
        "known-base-name-number",
        KNOWN,
        _write(
            "kb.json",
            lambda r: {
                **r,
                "base_parameters": [
                    {**r["base_parameters"][0], "name": 7},
                    *r["base_parameters"][1:],
                ],
            },
        ),
        "name must be a string",
    ),
    Case(
        "known-base-row-not-object",
        KNOWN,
        _write("kb.json", _known(base_parameters=[1, 2, 3])),
        "must be an object",
    ),
    Case(
        "known-base-duplicate-names",
        KNOWN,
        _write(
            "kb.json",
            lambda r: {**r, "base_parameters": [r["base_parameters"][0]] * 3, "covariance": None},
        ),
        "appears twice",
    ),
    Case("known-base-top-level-list", KNOWN, _write("kb.json", [1, 2]), "JSON object"),
    Case("torque-scale-gain-string", SCALE, _write("ts.json", _gains(gain="abc")), "finite number"),
    Case("torque-scale-gain-list", SCALE, _write("ts.json", _gains(gain=[1, 2])), "finite number"),
    Case("torque-scale-gain-true", SCALE, _write("ts.json", _gains(gain=True)), "finite number"),
    Case("torque-scale-gain-zero", SCALE, _write("ts.json", _gains(gain=0)), "positive number"),
    Case(
        "torque-scale-gain-negative", SCALE, _write("ts.json", _gains(gain=-2.0)), "positive number"
    ),
    Case(
        "torque-scale-gain-nan",
        SCALE,
        _write("ts.json", json.dumps(_gains()).replace("1.5", "NaN")),
        "finite number",
    ),
    Case(
        "torque-scale-not-determined",
        SCALE,
        _write("ts.json", _gains(determined=False)),
        "not determined",
    ),
    Case(
        "torque-scale-determined-string",
        SCALE,
        _write("ts.json", _gains(determined="yes")),
        "true or false",
    ),
    Case(
        "torque-scale-joint-number", SCALE, _write("ts.json", _gains(joint=3)), "must be a string"
    ),
    Case(
        "torque-scale-unknown-joint",
        SCALE,
        _write("ts.json", _gains(joint="elbow")),
        "unknown joint 'elbow'",
    ),
    Case(
        "torque-scale-other-robot",
        SCALE,
        _write("ts.json", {**GAINS, "robot": "ur5"}),
        "of robot 'ur5', not of 'msd'",
    ),
    Case(
        "torque-scale-rows-object",
        SCALE,
        _write("ts.json", {**GAINS, "drive_gains": {}}),
        "holds no 'drive_gains'",
    ),
    Case(
        "torque-scale-row-null",
        SCALE,
        _write("ts.json", {**GAINS, "drive_gains": [None]}),
        "must be an object",
    ),
    Case(
        "torque-scale-joint-twice",
        SCALE,
        _write("ts.json", {**GAINS, "drive_gains": GAINS["drive_gains"] * 2}),
        "appears twice",
    ),
    Case(
        "show-warnings-not-strings",
        ["show", "r.json"],
        _write("r.json", _tampered(warnings=[1, None])),
        "warnings",
    ),
    Case(
        "show-warnings-object",
        ["show", "r.json"],
        _write("r.json", _tampered(warnings={})),
        "warnings",
    ),
    Case(
        "show-relative-error-string",
        ["show", "r.json"],
        _write("r.json", _tampered(relative_error="x")),
        "relative_error",
    ),
    Case(
        "show-base-parameters-string",
        ["show", "r.json"],
        _write("r.json", _tampered(base_parameters="x")),
        "base_parameters",
    ),
    Case(
        "show-n-base-string",
        ["show", "r.json"],
        _write("r.json", _tampered(n_base="abc")),
        "n_base",
    ),
    Case("show-robot-number", ["show", "r.json"], _write("r.json", _tampered(robot=5)), "robot"),
    Case(
        "show-joints-object", ["show", "r.json"], _write("r.json", _tampered(joints={})), "joints"
    ),
    Case(
        "sidecar-joints-string",
        MONITOR,
        _write("arm.identified.json", _sidecar(joints="x")),
        "misses 'joints'",
    ),
    Case(
        "sidecar-armature-nan",
        MONITOR,
        _write(
            "arm.identified.json",
            json.dumps(_sidecar(joints={"j1": {"Ia": 0.5}, "j2": {}})).replace("0.5", "NaN"),
        ),
        r"joints\.j1\.Ia must be a finite number",
    ),
    Case(
        "sidecar-armature-negative",
        MONITOR,
        _write("arm.identified.json", _sidecar(joints={"j1": {"Ia": -0.1}, "j2": {}})),
        r"joints\.j1\.Ia must be a number >= 0",
    ),
    Case(
        "sidecar-armature-string",
        MONITOR,
        _write("arm.identified.json", _sidecar(joints={"j1": {"Ia": "big"}, "j2": {}})),
        "finite number",
    ),
    Case(
        "sidecar-friction-bool",
        MONITOR,
        _write("arm.identified.json", _sidecar(joints={"j1": {"fv": True}, "j2": {}})),
        "finite number",
    ),
    Case(
        "sidecar-terms-object",
        MONITOR,
        _write("arm.identified.json", _sidecar(joints={"j1": [1, 2], "j2": {}})),
        "must be an object",
    ),
    Case(
        "sidecar-active-numbers",
        MONITOR,
        _write("arm.identified.json", _sidecar(active_joints=[1, 2])),
        "must be a string",
    ),
    Case(
        "sidecar-unknown-joint",
        MONITOR,
        _write("arm.identified.json", _sidecar(joints={"j1": {}, "j9": {"Ia": 0.1}})),
        "j9",
    ),
    Case(
        "sidecar-locked-string",
        MONITOR,
        _write("arm.identified.json", _sidecar(locked_joints={"j2": "up"})),
        "finite number",
    ),
    Case(
        "sidecar-not-object",
        MONITOR,
        _write("arm.identified.json", [SIDECAR]),
        "not a manip_id sidecar",
    ),
]

# ----------------------------------------------------------- rule 5: physical user numbers
PHYSICAL = [
    Case(
        "urdf-two-parents",
        ["rank", "bad.urdf", "--samples", "20"],
        _two_parents,
        "link 'l2' is the child of two joints",
    ),
    Case(
        "urdf-zero-axis",
        ["rank", "bad.urdf", "--samples", "20"],
        _urdf('<axis xyz="0 1 0"/>', '<axis xyz="0 0 0"/>'),
        "axis of joint 'j2' is 0 0 0",
    ),
    Case(
        "urdf-axis-nan",
        ["rank", "bad.urdf", "--samples", "20"],
        _urdf('<axis xyz="0 1 0"/>', '<axis xyz="0 nan 0"/>'),
        "finite numbers",
    ),
    Case(
        "urdf-inverted-limits",
        ["rank", "bad.urdf", "--samples", "20"],
        _urdf('lower="-3" upper="3"', 'lower="3" upper="-3"'),
        "lower limit 3 > upper limit -3",
    ),
    Case(
        "urdf-negative-velocity-limit",
        ["rank", "bad.urdf", "--samples", "20"],
        _urdf('velocity="5"', 'velocity="-5"'),
        "negative velocity limit",
    ),
    Case(
        "urdf-limit-not-number",
        ["rank", "bad.urdf", "--samples", "20"],
        _urdf('upper="3"', 'upper="three"'),
        "bad.urdf",
    ),
    Case(
        "urdf-negative-mass-simulate",
        ["identify", "bad.urdf", "--simulate"],
        _urdf('<mass value="1.0"/>', '<mass value="-1.0"/>'),
        r"j2: mass m > 0",
    ),
    Case(
        "urdf-inertia-inf",
        ["rank", "bad.urdf", "--samples", "20"],
        _urdf('ixx="0.01"', 'ixx="inf"'),
        "ixx of link .l2. must be 1 finite numbers",
    ),
    Case(
        "drive-gains-mass-1e30",
        [*GAINS_CMD, "--payload-mass", "1e30"],
        None,
        "payload mass must be <=",
    ),
    Case(
        "drive-gains-com-far",
        [*GAINS_CMD, "--payload-mass", "1", "--payload-com", "100,0,0"],
        None,
        "centre of mass must lie within",
    ),
    Case(
        "drive-gains-inertia-not-physical",
        [
            *GAINS_CMD,
            "--payload-mass",
            "1",
            "--payload-com",
            "0,0,0",
            "--payload-inertia",
            "1,0,0.01,0,0,0.01",
        ],
        None,
        "not physical",
    ),
    Case(
        "drive-gains-inertia-negative",
        [
            *GAINS_CMD,
            "--payload-mass",
            "1",
            "--payload-com",
            "0,0,0",
            "--payload-inertia=-1,0,1,0,0,1",
        ],
        None,
        "not physical",
    ),
]


def _corrupted_bag(w: Path, result: dict) -> None:
    """A rosbag2 folder of 5 JointState messages, the third cut short (CDR that ends early)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    kind = "sensor_msgs/msg/JointState"
    state, header = store.types[kind], store.types["std_msgs/msg/Header"]
    stamp = store.types["builtin_interfaces/msg/Time"]
    with Writer(w / "cbag", version=8, storage_plugin=StoragePlugin.MCAP) as out:
        conn = out.add_connection("/joint_states", kind, typestore=store)
        for k in range(5):
            msg = state(
                header=header(stamp=stamp(sec=k + 1, nanosec=0), frame_id=""),
                name=["cart"],
                position=np.array([0.1 * k]),
                velocity=np.array([0.0]),
                effort=np.array([1.0]),
            )
            raw = bytes(store.serialize_cdr(msg, kind))
            out.write(conn, 10**9 * (k + 1), raw[:30] if k == 2 else raw)


THRESHOLDS = {
    "false_alarm": 0.001,
    "n_samples": 400,
    "rate": 0.0,
    "files": ["log.npz"],
    "joints": [
        {
            "name": "cart",
            "bound": 0.02,
            "noise_bound": 0.02,
            "model_bound": 0.0,
            "gain": 25.0,
            "filter_gain": 25.0,
            "method": "exponential tail",
            "rate": 0.0,
        }
    ],
}
WATCH = ["monitor", "msd", "--model", "r.json", "--data", "log.npz", "--thresholds", "t.json"]


def _thresholds(**row):
    return {**THRESHOLDS, "joints": [{**THRESHOLDS["joints"][0], **row}]}


MORE = [
    Case(
        "thresholds-joint-number",
        WATCH,
        _write("t.json", {**THRESHOLDS, "joints": [1]}),
        r"joints\[0\] must be an object",
    ),
    Case(
        "thresholds-bound-string",
        WATCH,
        _write("t.json", _thresholds(bound="x")),
        r"joints\[0\]\.bound must be a finite number",
    ),
    Case(
        "thresholds-bound-negative",
        WATCH,
        _write("t.json", _thresholds(bound=-1)),
        r"bound must be a number >= 0",
    ),
    Case(
        "thresholds-false-alarm-2",
        WATCH,
        _write("t.json", {**THRESHOLDS, "false_alarm": 2}),
        r"false_alarm must be a number <= 1",
    ),
    Case(
        "thresholds-n-samples-float",
        WATCH,
        _write("t.json", {**THRESHOLDS, "n_samples": 1.5}),
        "n_samples must be an integer",
    ),
    Case(
        "data-csv-not-utf8",
        ["identify", "msd", "--data", "bad.csv"],
        _write("bad.csv", b"t,q_cart\n\xff\xfe,1\n"),
        "bad.csv",
    ),
    Case(
        "data-npz-garbage",
        ["identify", "msd", "--data", "bad.npz"],
        _write("bad.npz", b"PK\x03\x04" + bytes(range(256))),
        "bad.npz",
    ),
    Case(
        "data-mcap-garbage",
        ["identify", "msd", "--data", "b.mcap"],
        _write("b.mcap", bytes(range(256)) * 4),
        "as a ROS 2 bag",
    ),
]

MORE.append(
    Case(
        "bag-corrupted-cdr",
        ["identify", "msd", "--data", "cbag"],
        _corrupted_bag,
        "message of '/joint_states' is not valid CDR",
    )
)

CASES = DOOR + SCHEMA + PHYSICAL + MORE


@pytest.mark.parametrize("case", [pytest.param(c, id=c.id) for c in CASES])
def test_input_case(case: Case, work: Path, result_doc: dict, capfd):  # noqa: F811
    for name, doc in (("r.json", result_doc), ("kb.json", result_doc)):
        (work / name).write_text(json.dumps(doc))
    (work / "arm.identified.json").write_text(json.dumps(SIDECAR))
    if case.setup is not None:
        case.setup(work, result_doc)
    capfd.readouterr()
    before = snapshot(work)
    status = main(list(case.argv))
    _, err = capfd.readouterr()
    lines = error_lines(err)
    assert "Traceback" not in err, err
    assert status == 2, (status, err)
    assert len(lines) == 1, lines
    assert re.match(r"manip-id( \w+)?: error: ", lines[0]), lines[0]
    assert re.search(case.match, lines[0]), lines[0]
    assert snapshot(work) == before  # inputs byte-identical, nothing left behind


# ------------------------------------------- properties: random structures to every reader
_SCALARS = (
    st.none()
    | st.booleans()
    | st.integers(-(10**20), 10**20)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=8)
)
_JSON = st.recursive(
    _SCALARS,
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4)
    ),
    max_leaves=20,
)


def _mutated(valid: dict) -> st.SearchStrategy:
    """``valid`` with one key (at the top or one level down) replaced by a random value."""

    def mutate(args):
        key, sub, value = args
        doc = json.loads(json.dumps(valid))
        keys = list(doc)
        k = keys[key % len(keys)]
        if isinstance(doc[k], list) and doc[k] and isinstance(doc[k][0], dict) and sub:
            row = doc[k][0]
            row[list(row)[sub % len(row)]] = value
        elif isinstance(doc[k], dict) and doc[k] and sub:
            doc[k][list(doc[k])[sub % len(doc[k])]] = value
        else:
            doc[k] = value
        return doc

    return st.tuples(st.integers(0, 99), st.integers(0, 9), _JSON).map(mutate)


def _only_ours(read: Callable[[Path], object], path: Path, doc) -> None:
    path.write_text(json.dumps(doc) if not isinstance(doc, str) else doc)
    try:
        read(path)
    except ManipIdError:
        pass


_PROPERTY = settings(
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


@pytest.fixture(scope="module")
def robots():
    from manip_id import load_robot

    return {"msd": load_robot("msd")}


@_PROPERTY
@given(doc=_JSON | st.deferred(lambda: _mutated(GAINS)))
def test_torque_scale_reader_raises_only_ours(doc, tmp_path, robots):
    from manip_id.payload import load_torque_scale

    _only_ours(lambda p: load_torque_scale(p, robots["msd"]), tmp_path / "ts.json", doc)


@_PROPERTY
@given(data=st.data())
def test_result_readers_raise_only_ours(data, tmp_path, result_doc):
    from manip_id.identification import load_result
    from manip_id.payload import load_known_base

    doc = data.draw(_JSON | _mutated(result_doc))
    for read in (load_result, load_known_base):
        _only_ours(read, tmp_path / "r.json", doc)


@_PROPERTY
@given(doc=_JSON | st.deferred(lambda: _mutated(SIDECAR)))
def test_sidecar_reader_raises_only_ours(doc, tmp_path):
    from manip_id import load_robot

    urdf = tmp_path / "arm.urdf"
    if not urdf.exists():
        arm_urdf(urdf)
    _only_ours(lambda p: load_robot(urdf, identified=p), tmp_path / "arm.identified.json", doc)


@_PROPERTY
@given(doc=_JSON | st.deferred(lambda: _mutated(THRESHOLDS)))
def test_thresholds_reader_raises_only_ours(doc, tmp_path):
    from manip_id.monitor import load_thresholds

    _only_ours(load_thresholds, tmp_path / "t.json", doc)


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value) if np.isfinite(value) else ("nan" if value != value else "inf")
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return "{" + ", ".join(f"{json.dumps(k)} = {_toml_value(v)}" for k, v in value.items()) + "}"


_TOML_SCALARS = st.booleans() | st.integers(-(10**15), 10**15) | st.floats() | st.text(max_size=6)
_TOML = st.recursive(
    _TOML_SCALARS,
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner, max_size=3)
    ),
    max_leaves=12,
)
_TABLES = st.sampled_from(["model", "joints", "excitation", "data", "other"])
_KEYS = st.sampled_from(
    [
        "friction",
        "armature",
        "spring",
        "active",
        "locked",
        "harmonics",
        "period",
        "margin",
        "acceleration_limit",
        "columns",
        "torque_scale",
        "time_unit",
        "x",
    ]
)


@_PROPERTY
@given(tables=st.dictionaries(_TABLES, st.dictionaries(_KEYS, _TOML, max_size=3), max_size=4))
def test_profile_reader_raises_only_ours(tables, tmp_path):
    from manip_id.robot.profiles import load_profile

    text = "\n".join(
        f"[{name}]\n" + "\n".join(f"{k} = {_toml_value(v)}" for k, v in body.items())
        for name, body in tables.items()
    )
    _only_ours(load_profile, tmp_path / "p.toml", text)


# --------------------------------------------------------------- API cases of rule 5
@pytest.mark.parametrize(
    "locked",
    [{"j2": float("nan")}, {"j2": "up"}, {"j2": [0.1, 0.2]}, [0.0, float("inf")]],
    ids=["nan", "string", "two-values", "vector-inf"],
)
def test_locked_positions_are_finite(locked, tmp_path):
    from manip_id import load_robot
    from manip_id.errors import InputError
    from manip_id.robot.model import JointSelection

    urdf = arm_urdf(tmp_path / "arm.urdf")
    with pytest.raises(InputError, match="locked"):
        load_robot(urdf, active_joints=JointSelection(["j1"], locked_configuration=locked))


@pytest.mark.parametrize(
    ("mass", "com", "inertia", "match"),
    [
        (1e30, None, None, "mass must be <="),
        (float("nan"), None, None, "mass must be > 0"),
        (1.0, [0, 0, 11], None, "within 10 m"),
        (1.0, [0, 0, 0], [1, 0, 0.01, 0, 0, 0.01], "not physical"),  # triangle inequality
        (1.0, [0, 0, 0], [0.01, 0.02, 0.01, 0, 0, 0.01], "not physical"),  # Ixy too large
    ],
)
def test_known_payload_is_physical(mass, com, inertia, match):
    from manip_id.errors import InputError
    from manip_id.payload import check_known_payload

    with pytest.raises(InputError, match=match):
        check_known_payload(mass, com, inertia)


def test_a_physical_payload_passes():
    """A solid box 0.1 x 0.2 x 0.3 m of 2 kg: I = m (b^2 + c^2) / 12 ... [kg m^2]."""
    from manip_id.payload import check_known_payload

    a, b, c, m = 0.1, 0.2, 0.3, 2.0
    inertia = [
        m * (b * b + c * c) / 12,
        0,
        m * (a * a + c * c) / 12,
        0,
        0,
        m * (a * a + b * b) / 12,
    ]
    mass, com, got = check_known_payload(m, [0.0, 0.0, 0.05], inertia)
    assert mass == m and np.allclose(got, inertia) and np.allclose(com, [0, 0, 0.05])


def test_the_door_refuses_a_path_swapped_after_the_stat(tmp_path, monkeypatch):
    """A regular file at ``stat`` that is a FIFO at ``open``: refused by ``fstat``, no block."""
    from manip_id._io import reading
    from manip_id.errors import DataError

    fifo = tmp_path / "swapped.json"
    os.mkfifo(fifo)
    real_stat = os.stat

    def fake_stat(path, *args, **kwargs):
        st_ = real_stat(path, *args, **kwargs)
        if Path(path) == fifo:  # looks like a small regular file to the first check
            return os.stat_result((0o100644, *tuple(st_)[1:6], 10, *tuple(st_)[7:10]))
        return st_

    monkeypatch.setattr(reading.os, "stat", fake_stat)
    with pytest.raises(DataError, match="FIFO"):
        reading.read_json(fifo, "result file")
