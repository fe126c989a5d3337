"""ROS 2 bags of sensor_msgs/JointState, written here with rosbags alone, read by manip_id."""

from __future__ import annotations

import numpy as np
import pytest
from _logs import log, save_npz
from conftest import get_robot

from manip_id.datasets import load_dataset
from manip_id.errors import DataError
from manip_id.identifiability import analyze
from manip_id.identification import FileOptions, PreprocessOptions, identify, scan_file

rosbags = pytest.importorskip("rosbags")
from rosbags.rosbag2 import StoragePlugin, Writer  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

STORE = get_typestore(Stores.ROS2_HUMBLE)
JS = "sensor_msgs/msg/JointState"


def _msg(stamp_ns, names, pos, vel, eff):
    T = STORE.types["builtin_interfaces/msg/Time"]
    H = STORE.types["std_msgs/msg/Header"]
    return STORE.types[JS](
        header=H(stamp=T(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id=""),
        name=list(names),
        position=np.asarray(pos, dtype=float),
        velocity=np.asarray(vel, dtype=float),
        effort=np.asarray(eff, dtype=float),
    )


def write_bag(path, topics, storage=StoragePlugin.MCAP):
    """topics: {topic: (msgtype, [(logtime_ns, msg), ...])}"""
    with Writer(path, version=9, storage_plugin=storage) as w:
        for topic, (msgtype, msgs) in topics.items():
            conn = w.add_connection(topic, msgtype, typestore=STORE)
            for logtime, msg in msgs:
                w.write(conn, logtime, STORE.serialize_cdr(msg, msgtype))
    return path


def shuffled_messages(robot, t, q, dq, tau, seed=0, stamp=True):
    """One message per sample, joints in a random order each time, plus a gripper joint."""
    rng = np.random.default_rng(seed)
    names = [*robot.dof_names, "gripper_finger"]
    out = []
    for k in range(t.shape[0]):
        order = rng.permutation(len(names))
        pos = np.append(q[k], 0.01)[order]
        vel = np.append(dq[k], 0.0)[order]
        eff = np.append(tau[k], 3.0)[order]
        ns = int(round(t[k] * 1e9))
        out.append((ns + 12345, _msg(ns if stamp else 0, [names[i] for i in order], pos, vel, eff)))
    return out


@pytest.fixture(scope="module")
def robot():
    return get_robot("ur5", friction="viscous,coulomb")


@pytest.fixture(scope="module")
def data(robot):
    t, q, dq, ddq, tau = log(robot, n=3000, rate=500.0, seed=11, t0=1000.0)
    return t, q, dq, ddq, tau


@pytest.mark.parametrize("storage", [StoragePlugin.MCAP, StoragePlugin.SQLITE3])
def test_bag_with_shuffled_joints_gives_the_npz_result(robot, data, tmp_path, storage):
    t, q, dq, ddq, tau = data
    bag = write_bag(
        tmp_path / "bag", {"/joint_states": (JS, shuffled_messages(robot, t, q, dq, tau))}, storage
    )
    npz = save_npz(tmp_path / "same.npz", robot, t, q, dq, ddq, tau, with_ddq=False)
    ds = load_dataset(bag, joint_names=list(robot.dof_names))
    np.testing.assert_array_equal(ds.q, q)
    np.testing.assert_array_equal(ds.tau, tau)
    np.testing.assert_allclose(ds.t, t, rtol=0, atol=1e-9)
    base = analyze(robot).base
    opts = PreprocessOptions(cutoff=10.0)
    from_bag = identify(robot, [bag], base=base, files=FileOptions(preprocess=opts, audit=False))
    from_npz = identify(robot, [npz], base=base, files=FileOptions(preprocess=opts, audit=False))
    assert from_bag.n_samples == from_npz.n_samples
    scale = np.abs(from_npz.estimate).max()
    np.testing.assert_allclose(from_bag.estimate, from_npz.estimate, rtol=0, atol=1e-7 * scale)


def test_bare_mcap_file_and_log_time_fallback(robot, data, tmp_path):
    t, q, dq, ddq, tau = data
    folder = write_bag(
        tmp_path / "b", {"/js": (JS, shuffled_messages(robot, t[:50], q, dq, tau, stamp=False))}
    )
    bare = next(folder.glob("*.mcap"))
    for path in (folder, bare):
        ds = load_dataset(path, joint_names=list(robot.dof_names))
        np.testing.assert_allclose(ds.t, t[:50] + 12345e-9, rtol=0, atol=1e-9)  # the log time


def test_topic_choice_and_errors(robot, data, tmp_path):
    t, q, dq, ddq, tau = data
    msgs = shuffled_messages(robot, t[:20], q, dq, tau)
    other = [(ns, STORE.types["std_msgs/msg/String"](data="x")) for ns, _ in msgs[:3]]
    bag = write_bag(
        tmp_path / "two",
        {
            "/a/joint_states": (JS, msgs),
            "/b/joint_states": (JS, msgs),
            "/log": ("std_msgs/msg/String", other),
        },
    )
    with pytest.raises(
        DataError,
        match="several sensor_msgs/msg/JointState topics: /a/joint_states, /b/joint_states",
    ):
        scan_file(robot, bag)
    with pytest.raises(
        DataError,
        match=r"has no topic '/c'; its topics: /a/joint_states .*/log \(std_msgs/msg/String\)",
    ):
        load_dataset(bag, topic="/c")
    with pytest.raises(DataError, match="carries std_msgs/msg/String"):
        load_dataset(bag, topic="/log")
    from manip_id.datasets import FileSpec

    assert scan_file(robot, FileSpec(bag, topic="/b/joint_states")).n == 20


def test_messages_without_effort_or_with_another_joint_set(robot, data, tmp_path):
    t, q, dq, ddq, tau = data
    msgs = shuffled_messages(robot, t[:30], q, dq, tau)
    ns, m = msgs[10]
    msgs[10] = (ns, _msg(ns, m.name, m.position, m.velocity, []))
    bag = write_bag(tmp_path / "noeff", {"/joint_states": (JS, msgs)})
    with pytest.raises(DataError, match="message 10 of '/joint_states' has no effort"):
        scan_file(robot, bag)
    msgs = shuffled_messages(robot, t[:30], q, dq, tau)
    ns, m = msgs[20]
    keep = [i for i, n in enumerate(m.name) if n != "elbow_joint"]
    msgs[20] = (
        ns,
        _msg(ns, [m.name[i] for i in keep], m.position[keep], m.velocity[keep], m.effort[keep]),
    )
    bag = write_bag(tmp_path / "set", {"/joint_states": (JS, msgs)})
    with pytest.raises(
        DataError, match="message 20 of '/joint_states' lists joints .* without elbow_joint"
    ):
        scan_file(robot, bag)
    with pytest.raises(DataError, match="lack joint"):
        load_dataset(bag, joint_names=["shoulder_pan_joint", "no_such_joint"])


def test_cli_reads_a_bag_with_a_topic(robot, data, tmp_path, capsys):
    import json

    from manip_id.cli import main

    t, q, dq, ddq, tau = data
    bag = write_bag(
        tmp_path / "cli", {"/arm/joint_states": (JS, shuffled_messages(robot, t, q, dq, tau))}
    )
    out = tmp_path / "o.json"
    argv = ["identify", "ur5", "--friction", "viscous,coulomb", "--data", f"{bag}@1:5"]
    assert main([*argv, "--topic", "/arm/joint_states", "--json", str(out)]) == 0
    rep = json.loads(out.read_text())
    assert rep["data_quality"][0]["format"] == "rosbag"
    assert rep["data_quality"][0]["n_samples"] == 2000
    assert main([*argv, "--topic", "/nope"]) == 2
    assert "its topics: /arm/joint_states (sensor_msgs/msg/JointState)" in capsys.readouterr().err


def test_fast_cdr_reader_agrees_with_rosbags():
    from manip_id.datasets.rosbag import decode_names, parse_joint_state

    rng = np.random.default_rng(3)
    H = STORE.types["std_msgs/msg/Header"]
    T = STORE.types["builtin_interfaces/msg/Time"]
    for _ in range(200):
        n = int(rng.integers(1, 9))
        names = ["j" * int(rng.integers(1, 7)) + str(i) for i in range(n)]
        msg = STORE.types[JS](
            header=H(
                stamp=T(sec=int(rng.integers(0, 2**31)), nanosec=int(rng.integers(0, 10**9))),
                frame_id="f" * int(rng.integers(0, 6)),
            ),
            name=names,
            position=rng.normal(size=n),
            velocity=rng.normal(size=n),
            effort=rng.normal(size=n),
        )
        raw = STORE.serialize_cdr(msg, JS)
        ref = STORE.deserialize_cdr(raw, JS)
        sec, nsec, key, pos, vel, eff = parse_joint_state(raw)
        assert (sec, nsec) == (ref.header.stamp.sec, ref.header.stamp.nanosec)
        assert decode_names(key) == list(ref.name)
        for a, b in ((pos, ref.position), (vel, ref.velocity), (eff, ref.effort)):
            np.testing.assert_array_equal(a, b)
    empty = STORE.types[JS](
        header=H(stamp=T(sec=1, nanosec=2), frame_id=""),
        name=["a"],
        position=np.zeros(1),
        velocity=np.zeros(1),
        effort=np.zeros(0),
    )
    assert parse_joint_state(STORE.serialize_cdr(empty, JS)) is None  # handed to rosbags
