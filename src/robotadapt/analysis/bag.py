"""Joint data from ROS bags of `sensor_msgs/msg/JointState` (docs/identification.md#data), read with `rosbags` (pure
Python, the `[identify]` extra): no ROS install.

DATA is a ROS 2 bag — its folder (with `metadata.yaml`) or one `.db3` / `.mcap` storage file — or a ROS 1 `.bag`.

- **Topic**: the one JointState topic of the bag, else the one named by `topic` (the CLI's `--topic`); the error lists
  them.
- **Joints** matched by name to the model's `joint_names`, in the model's order; other joints in the messages (a
  gripper's fingers) are ignored, messages holding none of the arm's joints (a gripper's own) skipped. A model without
  joint names takes the bag's joints in their order when they are exactly n. Positions and efforts are required; the
  velocities are used when every message has them, else q̇ is differentiated from q downstream.
- **Time** from each message's header stamp, the time the robot's controller gave the sample; a bag whose stamps are
  unset (zero) falls back to the bag's receive times, with a note: those carry the transport's jitter too. Messages are
  put in stamp order (a bag stores them in the order they arrived); time starts at 0 at the first message, computed in
  integer nanoseconds so that epoch stamps lose no precision.

ROS units are SI (rad or m, rad/s or m/s, N·m or N), as the identification wants. Each failure is one
:class:`~robotadapt.validation.ConfigError` line naming what is wrong and what to do; each thing reading decided is one
line of the notes returned.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..validation import ConfigError

Array = np.ndarray

JOINT_STATE = "sensor_msgs/msg/JointState"


def _names(names: Sequence[str], limit: int = 6) -> str:
    shown = ", ".join(names[:limit])
    return shown + (f", … ({len(names)} in all)" if len(names) > limit else "")


def _stamp(ns: int) -> str:
    """A stamp as ROS tools print it, seconds.nanoseconds."""
    return f"{ns // 1_000_000_000}.{ns % 1_000_000_000:09d}"


def read_bag(path: Path, n: int, *, joint_names: Sequence[str] | None = None,
             topic: str | None = None) -> tuple[Array, Array, Array | None, Array, tuple[str, ...]]:
    """`t` (N,) from 0, `q` (N, n), `dq` (N, n) or None, `tau` (N, n) and the notes of the JointState messages of the bag
    `path` (module docstring), the joints in the order of `joint_names` (the model's)."""
    source = path.name or str(path)
    if joint_names is not None and len(joint_names) != n:
        raise ConfigError("DATA", f"{len(joint_names)} joint names given for a robot of {n} joints")
    try:
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise ConfigError("DATA", f"reading the ROS bag {source!r} needs the rosbags package: pip install rosbags "
                          "(or the [identify] extra)") from None
    ros1 = path.suffix == ".bag"
    if path.is_dir() and not (path / "metadata.yaml").is_file():
        raise ConfigError("DATA", f"{source!r} is a folder without metadata.yaml: give a ROS 2 bag's folder (or its "
                          ".db3 / .mcap file), a ROS 1 .bag, a result.npz or a .csv")
    from rosbags.rosbag1 import Reader as Reader1
    from rosbags.rosbag2 import Reader as Reader2

    # JointState and its Header are the same in every ROS 2 release (and in ROS 1 but for the header's seq)
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    deserialize = store.deserialize_ros1 if ros1 else store.deserialize_cdr
    try:
        reader: Any = Reader1(path) if ros1 else Reader2(path)
        reader.open()
    except Exception as exc:  # rosbags raises its own errors, sqlite's, yaml's, OSError: all mean "not a bag I can read"
        raise ConfigError("DATA", f"cannot read {source!r} as a ROS {1 if ros1 else 2} bag: "
                          f"{(str(exc) or type(exc).__name__).splitlines()[0]}") from None
    try:
        connections = _topic(reader.connections, topic, source)
        chosen = connections[0].topic
        for c in connections:
            fmt = getattr(getattr(c, "ext", None), "serialization_format", "cdr")
            if not ros1 and fmt != "cdr":
                raise ConfigError("DATA", f"{source}: {chosen} is serialised as {fmt!r}, not CDR: re-record it with the "
                                  "default serialisation")
        messages = []
        for i, (c, received, raw) in enumerate(reader.messages(connections=connections)):
            try:
                m: Any = deserialize(raw, c.msgtype)
            except Exception as exc:  # a message of another definition under the same type name
                raise ConfigError("DATA", f"{source}: message {i} on {chosen} is no readable JointState: "
                                  f"{(str(exc) or type(exc).__name__).splitlines()[0]}") from None
            stamp = int(m.header.stamp.sec) * 1_000_000_000 + int(m.header.stamp.nanosec)
            messages.append((stamp, int(received), tuple(m.name), m.position, m.velocity, m.effort))
    finally:
        reader.close()
    if not messages:
        raise ConfigError("DATA", f"{source}: the topic {chosen} holds no messages")
    return _columns(messages, n, joint_names, source, chosen)


def _topic(connections: Sequence[Any], topic: str | None, source: str) -> list[Any]:
    """The connections of the JointState topic to read."""
    joint_states = sorted({c.topic for c in connections if c.msgtype == JOINT_STATE})
    if not joint_states:
        others = sorted({f"{c.topic} ({c.msgtype})" for c in connections})
        raise ConfigError("DATA", f"{source} has no {JOINT_STATE} topic (its topics: {_names(others) or 'none'}): "
                          "record the arm's joint states")
    if topic is None:
        if len(joint_states) > 1:
            raise ConfigError("DATA", f"{source} has {len(joint_states)} JointState topics, {_names(joint_states)}: "
                              "choose one with --topic")
        topic = joint_states[0]
    elif topic not in joint_states:
        raise ConfigError("DATA", f"{source} has no JointState topic {topic!r}; its JointState "
                          f"topic{'s are' if len(joint_states) > 1 else ' is'} {_names(joint_states)}")
    return [c for c in connections if c.topic == topic and c.msgtype == JOINT_STATE]


def _columns(messages: list[tuple[int, int, tuple[str, ...], Array, Array, Array]], n: int,
             joint_names: Sequence[str] | None, source: str,
             topic: str) -> tuple[Array, Array, Array | None, Array, tuple[str, ...]]:
    """The messages as columns, joints matched by name, in time order, and the notes."""
    notes = []
    bag_names = list(dict.fromkeys(name for m in messages for name in m[2]))
    if joint_names is None:
        first = messages[0][2]
        if len(first) != n:
            raise ConfigError("DATA", f"{source}: the JointState messages on {topic} name {len(first)} joints "
                              f"({_names(list(first))}), the robot has {n} and its model names none to match them by: "
                              "record only the arm's joints, or use a model with joint names (a URDF)")
        wanted: list[str] = list(first)
        notes.append(f"{source}: the robot's model names no joints: its {n} joints taken in the bag's order "
                     f"{_names(wanted)}")
    else:
        wanted = [str(x) for x in joint_names]
    missing = [name for name in wanted if name not in bag_names]
    if len(missing) == len(wanted):
        raise ConfigError("DATA", f"{source}: none of the robot's joints ({_names(wanted)}) is in the JointState messages "
                          f"on {topic}, which name {_names(bag_names)}: another topic, or a model of another arm?")
    if missing:
        raise ConfigError("DATA", f"{source}: the JointState messages on {topic} lack the robot's joint"
                          f"{'s' * (len(missing) > 1)} {_names(missing)} (they name {_names(bag_names)}): record "
                          "every joint of the arm")
    index: dict[tuple[str, ...], Array | None] = {}
    rows: list[tuple[int, int, int, Array, Array | None, Array | None]] = []
    skipped = 0
    for i, (stamp, received, names, position, velocity, effort) in enumerate(messages):
        if names not in index:
            found = [names.index(w) if w in names else -1 for w in wanted]
            if all(k < 0 for k in found):
                index[names] = None
            elif any(k < 0 for k in found):
                lacking = [w for w, k in zip(wanted, found, strict=True) if k < 0]
                raise ConfigError("DATA", f"{source}: message {i} on {topic} names some of the robot's joints but not "
                                  f"{_names(lacking)}: record every joint of the arm in each message")
            else:
                index[names] = np.array(found)
        cols = index[names]
        if cols is None:
            skipped += 1
            continue
        for field, values in (("position", position), ("effort", effort)):
            if len(values) != len(names) and (field == "position" or len(values)):
                raise ConfigError("DATA", f"{source}: message {i} on {topic} (stamp {_stamp(stamp)} s) has "
                                  f"{len(names)} joint names but {len(values)} {field} values: a JointState gives "
                                  "one for every joint it names")
        rows.append((i, stamp, received, position[cols], velocity[cols] if len(velocity) == len(names) else None,
                     effort[cols] if len(effort) else None))
    no_effort = [r for r in rows if r[5] is None]
    if rows and len(no_effort) == len(rows):
        raise ConfigError("DATA", f"{source}: the JointState messages on {topic} have no effort (torque) values, the "
                          "field is empty: identification needs the joint torques; record the hardware's effort state "
                          "interface (or log τ another way, as a CSV)")
    if no_effort:
        i, stamp = no_effort[0][:2]
        raise ConfigError("DATA", f"{source}: {len(no_effort)} of the messages on {topic} have no effort (torque) "
                          f"values, the first message {i} (stamp {_stamp(stamp)} s): identification needs the torque "
                          "of every sample")
    if skipped:
        notes.append(f"{source}: skipped {skipped} message{'s' * (skipped > 1)} on {topic} holding none of the robot's "
                     "joints (another device publishing on the same topic)")
    stamps = np.array([r[1] for r in rows], dtype=np.int64)
    unset = int(np.count_nonzero(stamps == 0))
    if unset:
        stamps = np.array([r[2] for r in rows], dtype=np.int64)
        notes.append(f"{source}: {'the' if unset == len(rows) else f'{unset} of the'} header stamps on {topic} "
                     f"{'are' if unset > 1 else 'is'} unset (zero): time from the bag's receive times instead, which "
                     "carry the transport's jitter too")
    order = np.argsort(stamps, kind="stable")
    if np.any(order != np.arange(order.size)):
        moved = int(np.count_nonzero(order != np.arange(order.size)))
        notes.append(f"{source}: {moved} messages on {topic} were stored out of stamp order: put in stamp order")
    q = np.array([rows[k][3] for k in order], dtype=float)
    tau = np.array([rows[k][5] for k in order], dtype=float)
    no_velocity = sum(r[4] is None for r in rows)
    dq: Array | None = None
    if not no_velocity:
        dq = np.array([rows[k][4] for k in order], dtype=float)
    else:
        notes.append(f"{source}: {'no message' if no_velocity == len(rows) else f'{no_velocity} of the messages'} on "
                     f"{topic} {'carries' if no_velocity == len(rows) else 'lack'} velocities: q̇ differentiated "
                     "from q")
    stamps = stamps[order]
    t = (stamps - stamps[0]).astype(float) / 1e9
    ignored = [b for b in bag_names if b not in wanted]
    notes.insert(0, f"{source}: {len(rows)} JointState messages on {topic}, joints {_names(wanted)}"
                 + (" matched by name" if joint_names is not None else "")
                 + (f" (ignored: {_names(ignored)})" if ignored else ""))
    return t, q, dq, tau, tuple(notes)
