"""ROS bags of sensor_msgs/msg/JointState as identification data (robotadapt.analysis.bag through joint_data.read): bags
written here with rosbags' own writer, read back with the joints matched by name, and each way a bag can fall short
refused in one line."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags", reason="rosbags (the [identify] extra) reads ROS bags")

from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import StoragePlugin, Writer  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from robotadapt.analysis.joint_data import read  # noqa: E402
from robotadapt.validation import ConfigError  # noqa: E402

STORE = get_typestore(Stores.ROS2_HUMBLE)
JOINT_STATE = "sensor_msgs/msg/JointState"
EPOCH = 1_700_000_000 * 10**9  # ns: stamps as a robot's clock gives them
PANDA = tuple(f"panda_joint{i}" for i in range(1, 8))
FINGER = "panda_finger_joint1"


def message(stamp: int, names, position, velocity=(), effort=(), store=STORE) -> object:
    """A JointState stamped `stamp` (ns) of the store's ROS version (ROS 1's header has a `seq` more)."""
    types = store.types
    Header = types["std_msgs/msg/Header"]
    time = types["builtin_interfaces/msg/Time"](sec=stamp // 10**9, nanosec=stamp % 10**9)
    header = Header(seq=0, stamp=time, frame_id="") if "seq" in Header.__dataclass_fields__ else Header(stamp=time,
                                                                                                          frame_id="")
    return types[JOINT_STATE](header=header, name=list(names), position=np.array(position, dtype=float),
                              velocity=np.array(velocity, dtype=float), effort=np.array(effort, dtype=float))


def write_bag(path: Path, topics: dict[str, list[tuple[int, object]]], storage=StoragePlugin.SQLITE3) -> Path:
    """A ROS 2 bag at `path` of the messages (receive time in ns, message) of each topic."""
    with Writer(path, version=9, storage_plugin=storage) as writer:
        for topic, messages in topics.items():
            connection = writer.add_connection(topic, JOINT_STATE, typestore=STORE)
            for received, msg in messages:
                writer.write(connection, received, STORE.serialize_cdr(msg, JOINT_STATE))
    return path


def arm_log(names: tuple[str, ...], t: np.ndarray, seed: int = 0) -> dict[str, np.ndarray]:
    """q, q̇, τ of each joint of `names` at the times `t`: smooth, distinct per joint."""
    rng = np.random.default_rng(seed)
    a, w, c = rng.uniform(0.2, 1.0, (3, len(names)))
    phase = t[:, None] * (1 + 3 * w) + c * 6
    return {"q": a * np.sin(phase), "dq": a * (1 + 3 * w) * np.cos(phase), "tau": 10 * a * np.cos(phase) + c}


def arm_messages(names: tuple[str, ...], t: np.ndarray, log: dict[str, np.ndarray], extra: tuple[str, ...] = (),
                 seed: int = 1, effort: bool = True, velocity: bool = True,
                 stamps: bool = True) -> list[tuple[int, object]]:
    """One JointState per time, the joints (and `extra` ones, value 0.04) in a shuffled order, received 0.3 ms after
    their stamp."""
    order = np.random.default_rng(seed).permutation(len(names) + len(extra))
    all_names = [*names, *extra]
    out = []
    for k, tk in enumerate(t):
        stamp = EPOCH + round(tk * 1e9)

        def row(values, k=k):
            return np.r_[values[k], np.full(len(extra), 0.04)][order]

        out.append((stamp + 300_000, message(stamp if stamps else 0, [all_names[i] for i in order], row(log["q"]),
                                             row(log["dq"]) if velocity else (), row(log["tau"]) if effort else ())))
    return out


@pytest.mark.parametrize("names", [("shoulder", "elbow"), PANDA], ids=["2 joints", "7 joints"])
@pytest.mark.parametrize("storage, as_file", [(StoragePlugin.SQLITE3, False), (StoragePlugin.SQLITE3, True),
                                              (StoragePlugin.MCAP, False), (StoragePlugin.MCAP, True)],
                         ids=["db3 folder", "db3 file", "mcap folder", "mcap file"])
def test_a_bag_reads_back_with_the_joints_matched_by_name(tmp_path, names, storage, as_file):
    """Joints in a shuffled order with a gripper finger among them, at 1 kHz: q, q̇ and τ in the model's order equal what
    was written, time from the header stamps (from 0), one note naming the topic, the joints and the one ignored."""
    t = np.arange(400) * 1e-3
    log = arm_log(names, t)
    bag = write_bag(tmp_path / "bag", {"/joint_states": arm_messages(names, t, log, extra=(FINGER,))}, storage)
    path = next(bag.glob("*.db3" if storage == StoragePlugin.SQLITE3 else "*.mcap")) if as_file else bag
    data = read(path, len(names), joint_names=names)
    assert np.allclose(data.t, t, rtol=0, atol=1e-12) and data.t[0] == 0.0
    assert np.array_equal(data.q, log["q"]) and np.array_equal(data.tau, log["tau"])
    assert data.dq is not None and np.array_equal(data.dq, log["dq"])
    shown = ", ".join(names[:6]) + (", … (7 in all)" if len(names) == 7 else "")
    assert data.notes == (f"{path.name}: 400 JointState messages on /joint_states, joints {shown} matched by name "
                          f"(ignored: {FINGER})",)


def test_a_bag_with_jittered_stamps_is_resampled_like_a_log(tmp_path):
    """Stamps 0.7–9 ms apart: the same resampling as a CSV (its note after the bag's), q within 1e-6 of the truth."""
    t = np.r_[0.0, np.cumsum(np.random.default_rng(3).uniform(0.7e-3, 9e-3, 1500))]
    log = arm_log(PANDA, t)
    bag = write_bag(tmp_path / "bag", {"/joint_states": arm_messages(PANDA, t, log)})
    data = read(bag, 7, joint_names=PANDA)
    assert len(data.notes) == 2 and "uniform 206 Hz" in data.notes[1] and "q and q̇ by cubic spline" in data.notes[1]
    assert np.allclose(np.diff(data.t), 1 / 206, rtol=0, atol=1e-12)
    truth = arm_log(PANDA, data.t)
    assert np.max(np.abs(data.q - truth["q"])) < 1e-6 and np.max(np.abs(data.tau - truth["tau"])) < 1e-2


def test_unset_header_stamps_fall_back_to_the_receive_time_with_a_note(tmp_path):
    t = np.arange(200) * 2e-3
    log = arm_log(PANDA, t)
    bag = write_bag(tmp_path / "bag", {"/joint_states": arm_messages(PANDA, t, log, stamps=False)})
    data = read(bag, 7, joint_names=PANDA)
    assert np.allclose(data.t, t, rtol=0, atol=1e-12) and np.array_equal(data.q, log["q"])
    assert data.notes[1] == ("bag: the header stamps on /joint_states are unset (zero): time from the bag's receive "
                             "times instead, which carry the transport's jitter too")


def test_messages_stored_out_of_stamp_order_are_put_in_order(tmp_path):
    t = np.arange(100) * 1e-3
    log = arm_log(PANDA, t)
    messages = arm_messages(PANDA, t, log)
    messages[40], messages[41] = (messages[40][0], messages[41][1]), (messages[41][0], messages[40][1])
    data = read(write_bag(tmp_path / "bag", {"/joint_states": messages}), 7, joint_names=PANDA)
    assert np.array_equal(data.q, log["q"]) and "2 messages on /joint_states were stored out of stamp order" in \
        data.notes[1]


def test_a_grippers_own_messages_on_the_same_topic_are_skipped(tmp_path):
    """joint_state_publisher merging the arm's and the gripper's states: the gripper's messages hold none of the arm's
    joints and are skipped, counted in a note."""
    t = np.arange(100) * 1e-3
    log = arm_log(PANDA, t)
    gripper = [(EPOCH + k * 10**7 + 5, message(EPOCH + k * 10**7 + 5, [FINGER, "panda_finger_joint2"], [0.04, 0.04],
                                               [0.0, 0.0], [0.0, 0.0])) for k in range(10)]
    bag = write_bag(tmp_path / "bag", {"/joint_states": sorted(arm_messages(PANDA, t, log) + gripper,
                                                               key=lambda m: m[0])})
    data = read(bag, 7, joint_names=PANDA)
    assert np.array_equal(data.q, log["q"]) and data.notes[1] == (
        "bag: skipped 10 messages on /joint_states holding none of the robot's joints (another device publishing on "
        "the same topic)")


def test_a_bag_without_velocities_leaves_them_to_the_derivative(tmp_path):
    t = np.arange(100) * 1e-3
    bag = write_bag(tmp_path / "bag", {"/joint_states": arm_messages(PANDA, t, arm_log(PANDA, t), velocity=False)})
    data = read(bag, 7, joint_names=PANDA)
    assert data.dq is None and data.notes[1] == ("bag: no message on /joint_states carries velocities: q̇ "
                                                 "differentiated from q")


def test_a_model_without_joint_names_takes_the_bags_order_when_the_count_matches(tmp_path):
    t = np.arange(100) * 1e-3
    log = arm_log(("a", "b"), t)
    ordered = write_bag(tmp_path / "ordered", {"/joint_states": [
        (EPOCH + k * 10**6, message(EPOCH + k * 10**6, ["a", "b"], log["q"][k], log["dq"][k], log["tau"][k]))
        for k in range(t.size)]})
    data = read(ordered, 2)
    assert np.array_equal(data.q, log["q"])
    assert "the robot's model names no joints: its 2 joints taken in the bag's order a, b" in data.notes[1]
    extra = write_bag(tmp_path / "extra", {"/joint_states": arm_messages(("a", "b"), t, log, extra=(FINGER,))})
    with pytest.raises(ConfigError, match=r"name 3 joints \(.*\), the robot has 2 and its model names none"):
        read(extra, 2)


def test_a_ros1_bag_reads_too(tmp_path):
    store = get_typestore(Stores.ROS1_NOETIC)
    t = np.arange(50) * 1e-3
    log = arm_log(("shoulder", "elbow"), t)
    with Writer1(tmp_path / "arm.bag") as writer:
        connection = writer.add_connection("/joint_states", JOINT_STATE, typestore=store)
        for k in range(t.size):
            msg = message(EPOCH + k * 10**6, ["elbow", "shoulder"], log["q"][k, ::-1], log["dq"][k, ::-1],
                          log["tau"][k, ::-1], store=store)
            writer.write(connection, EPOCH + k * 10**6, store.serialize_ros1(msg, JOINT_STATE))
    data = read(tmp_path / "arm.bag", 2, joint_names=("shoulder", "elbow"))
    assert np.array_equal(data.q, log["q"]) and np.array_equal(data.tau, log["tau"])


def one_line(call) -> str:
    with pytest.raises(ConfigError) as err:
        call()
    message = str(err.value)
    assert "\n" not in message and message.startswith("DATA: ")
    return message


def test_a_bag_missing_a_joint_is_one_clear_line(tmp_path):
    t = np.arange(50) * 1e-3
    arm = PANDA[:3] + PANDA[4:]
    bag = write_bag(tmp_path / "bag", {"/joint_states": arm_messages(arm, t, arm_log(arm, t), extra=(FINGER,))})
    message = one_line(lambda: read(bag, 7, joint_names=PANDA))
    assert message.startswith("DATA: bag: the JointState messages on /joint_states lack the robot's joint panda_joint4 "
                              "(they name ")
    assert message.endswith("): record every joint of the arm")


def test_a_bag_of_another_arm_is_one_clear_line(tmp_path):
    t = np.arange(50) * 1e-3
    bag = write_bag(tmp_path / "bag", {"/joint_states": arm_messages(("a", "b"), t, arm_log(("a", "b"), t))})
    assert "none of the robot's joints (shoulder, elbow) is in the JointState messages on /joint_states" in one_line(
        lambda: read(bag, 2, joint_names=("shoulder", "elbow")))


def test_a_bag_with_empty_effort_is_one_clear_line(tmp_path):
    t = np.arange(50) * 1e-3
    bag = write_bag(tmp_path / "bag", {"/joint_states": arm_messages(PANDA, t, arm_log(PANDA, t), effort=False)})
    assert one_line(lambda: read(bag, 7, joint_names=PANDA)) == (
        "DATA: bag: the JointState messages on /joint_states have no effort (torque) values, the field is empty: "
        "identification needs the joint torques; record the hardware's effort state interface (or log τ another way, "
        "as a CSV)")


def test_a_bag_where_some_messages_lack_effort_names_the_first(tmp_path):
    t = np.arange(50) * 1e-3
    log = arm_log(PANDA, t)
    messages = arm_messages(PANDA, t, log)
    messages[7] = arm_messages(PANDA, t, log, effort=False)[7]
    message = one_line(lambda: read(write_bag(tmp_path / "bag", {"/joint_states": messages}), 7, joint_names=PANDA))
    assert "1 of the messages on /joint_states have no effort (torque) values, the first message 7 (stamp " \
        "1700000000.007000000 s)" in message


def test_two_joint_state_topics_without_one_chosen_is_one_line_listing_them(tmp_path):
    t = np.arange(50) * 1e-3
    log = arm_log(PANDA, t)
    bag = write_bag(tmp_path / "bag", {"/joint_states": arm_messages(PANDA, t, log),
                                       "/franka/joint_states": arm_messages(PANDA, t, log, seed=2)})
    assert one_line(lambda: read(bag, 7, joint_names=PANDA)) == (
        "DATA: bag has 2 JointState topics, /franka/joint_states, /joint_states: choose one with --topic")
    data = read(bag, 7, joint_names=PANDA, topic="/franka/joint_states")
    assert np.array_equal(data.q, log["q"]) and "on /franka/joint_states" in data.notes[0]
    assert one_line(lambda: read(bag, 7, joint_names=PANDA, topic="/arm")) == (
        "DATA: bag has no JointState topic '/arm'; its JointState topics are /franka/joint_states, /joint_states")


def test_what_is_no_bag_is_one_clear_line(tmp_path):
    (tmp_path / "folder").mkdir()
    assert "'folder' is a folder without metadata.yaml" in one_line(lambda: read(tmp_path / "folder", 2))
    (tmp_path / "junk.db3").write_bytes(b"not a database" * 10)
    assert re.match(r"DATA: cannot read 'junk\.db3' as a ROS 2 bag: ", one_line(lambda: read(tmp_path / "junk.db3", 2)))
    other = tmp_path / "other"
    with Writer(other, version=9) as writer:
        connection = writer.add_connection("/chatter", "std_msgs/msg/String", typestore=STORE)
        writer.write(connection, 1, STORE.serialize_cdr(STORE.types["std_msgs/msg/String"](data="hi"),
                                                        "std_msgs/msg/String"))
    assert one_line(lambda: read(other, 2)) == ("DATA: other has no sensor_msgs/msg/JointState topic (its topics: "
                                               "/chatter (std_msgs/msg/String)): record the arm's joint states")


def test_identify_reads_a_panda_bag_as_it_comes(tmp_path, capsys):
    """`robotadapt identify BAG --robot panda-slotine-li`: a bag of an exciting Panda run, stamps jittered 0.7–9 ms
    as the robot's controller writes them, joints shuffled with a finger among them; identified to the truth's base
    parameters within the noise, the resampling said in one line."""
    from robotadapt.cli import main
    from robotadapt.robots.identifiability import base_parameters
    from robotadapt.studies.scenarios import load
    from robotadapt.trajectories import fourier

    setup = load("panda-slotine-li").setup
    model, phi = setup.controller.model, np.asarray(setup.plant.phi)
    rng = np.random.default_rng(42)
    t = np.cumsum(np.r_[0.0, rng.uniform(0.0007, 0.009, 2400)])  # about 11 s
    a, b = np.random.default_rng(27).uniform(-0.4, 0.4, (2, 7, 4))
    ref = fourier(7, 4.0, a, b, [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])(t)
    tau = np.asarray(model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)) @ phi
    log = {"q": np.asarray(ref.q_des), "dq": np.asarray(ref.dq_des), "tau": tau + 0.01 * rng.standard_normal(tau.shape)}
    bag = write_bag(tmp_path / "panda_bag", {"/joint_states": arm_messages(PANDA, t, log, extra=(FINGER,))})
    out = tmp_path / "out"
    assert main(["identify", str(bag), "--robot", "panda-slotine-li", "--out", str(out), "--no-plots"]) == 0
    printed = capsys.readouterr().out
    assert "resampled to a uniform" in printed and "panda_finger_joint1" in printed
    record = __import__("json").loads((out / "identified.json").read_text())
    K = base_parameters(model).K
    error = np.linalg.norm(np.asarray(record["base"]["wls"]) - K @ phi) / np.linalg.norm(K @ phi)
    assert error < 0.02, error
