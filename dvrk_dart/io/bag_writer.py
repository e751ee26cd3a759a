"""Writing ROS bags: joint-state topics as a real dVRK publishes them (ROS 2
mcap/sqlite3 folders or ROS 1 .bag files), and a simulated run exported as one.
Reading them is `bags.py`."""

from __future__ import annotations

import heapq
import os
import shutil
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.bags import JOINT_STATE, NS, STORAGES, first_line
from dvrk_dart.model.description import PsmModel


@dataclass(frozen=True)
class JointStates:
    """One topic of joint states to write: names, times (s) and values (dVRK units);
    velocity and effort may be None (commands carry positions only)."""

    topic: str
    names: tuple[str, ...]
    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray | None = None
    effort: np.ndarray | None = None


def arm_joint_states(model: PsmModel, arm: str | None, t, q, dq=None, tau=None, suffix: str = "measured_js") -> list[JointStates]:
    """The topics of `model`'s arm (its joints, then a PSM's jaw on its own
    topic) from model-coordinate arrays (N, 7): mapped to the dVRK's joint values."""
    card, motor_map = model.dvrk_topics, model.motor_map
    arm = arm or card.namespace
    position = motor_map.positions_to_dvrk(q)
    velocity = None if dq is None else motor_map.positions_to_dvrk(dq)
    effort = None if tau is None else motor_map.efforts_to_dvrk(tau)
    k = len(card.arm_joints)

    def part(cols):
        return [None if a is None else a[:, cols] for a in (position, velocity, effort)]

    t = np.asarray(t, dtype=float)
    states = [JointStates(f"/{arm}/{suffix}", card.arm_joints, t, *part(slice(0, k)))]
    if card.jaw_joints:
        states.append(JointStates(f"/{arm}/jaw/{suffix}", card.jaw_joints, t, *part(slice(k, k + len(card.jaw_joints)))))
    return states


def _messages(typestore, states: JointStates, stamps_ns: np.ndarray, ros1: bool):
    types = typestore.types
    Time, Header, JointState = types["builtin_interfaces/msg/Time"], types["std_msgs/msg/Header"], types[JOINT_STATE]
    empty = np.zeros(0)
    for i, stamp in enumerate(stamps_ns):
        stamp = int(stamp)
        time = Time(sec=stamp // NS, nanosec=stamp % NS)
        header = Header(seq=i, stamp=time, frame_id="") if ros1 else Header(stamp=time, frame_id="")
        yield stamp, JointState(
            header=header,
            name=list(states.names),
            position=np.ascontiguousarray(states.position[i], dtype=np.float64),
            velocity=empty if states.velocity is None else np.ascontiguousarray(states.velocity[i], dtype=np.float64),
            effort=empty if states.effort is None else np.ascontiguousarray(states.effort[i], dtype=np.float64),
        )


def _stream(order: int, connection, receive_ns: np.ndarray, messages) -> Iterator[tuple]:
    for received, (_, msg) in zip(receive_ns, messages):
        yield int(received), order, connection, msg


def write_bag(out: str | os.PathLike, topics: list[JointStates], storage: str = "mcap", stamps_ns: dict[str, np.ndarray] | None = None,
              custom_data: dict[str, str] | None = None) -> Path:
    """Write joint-state topics as a bag: a ROS 2 folder (mcap or sqlite3
    storage) or a ROS 1 .bag file. Built beside `out` and moved there whole;
    `out` must not exist (a bag is never replaced). `stamps_ns` overrides the
    header stamps per topic (receive times stay t); `custom_data`: what the bag
    was made from, in a ROS 2 bag's metadata.yaml (a ROS 1 bag has no place for it)."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.typesys import Stores, get_typestore

    out = Path(out)
    if storage not in STORAGES:
        raise DvrkDartError(f"bag storage must be one of {', '.join(STORAGES)}, not '{storage}'")
    if out.exists() or out.is_symlink():
        raise DvrkDartError(f"{out}: exists; a bag is never overwritten (choose a new name or remove it)")
    ros1 = storage == "ros1"
    typestore = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    out.parent.mkdir(parents=True, exist_ok=True)
    building = out.parent / f".{out.name}.building-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    building.mkdir()
    try:
        target = building / out.name
        if ros1:
            writer = Writer1(target)
        else:
            plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
            writer = Writer2(target, version=Writer2.VERSION_LATEST, storage_plugin=plugin)
        serialize = typestore.serialize_ros1 if ros1 else typestore.serialize_cdr
        for key, value in (custom_data or {}).items() if not ros1 else ():
            writer.set_custom_data(key, value)
        with writer:
            streams = []
            for order, states in enumerate(topics):
                connection = writer.add_connection(states.topic, JOINT_STATE, typestore=typestore)
                receive_ns = np.round(np.asarray(states.t) * NS).astype(np.int64)
                header_ns = receive_ns if stamps_ns is None or states.topic not in stamps_ns else stamps_ns[states.topic]
                streams.append(_stream(order, connection, receive_ns, _messages(typestore, states, header_ns, ros1)))
            # in time order across topics, as a recorder writes them (players replay in file order)
            for received, _, connection, msg in heapq.merge(*streams, key=lambda item: (item[0], item[1])):
                writer.write(connection, received, serialize(msg, JOINT_STATE))
        if out.exists() or out.is_symlink():
            raise DvrkDartError(f"{out}: written by another process meanwhile; a bag is never overwritten")
        try:
            os.replace(target, out)
        except OSError:  # created between the check and the move
            raise DvrkDartError(f"{out}: written by another process meanwhile; a bag is never overwritten") from None
    finally:
        shutil.rmtree(building, ignore_errors=True)
    return out


def export_run(run_dir: Path, out: Path, model: PsmModel, arm: str | None = None, storage: str = "mcap") -> Path:
    """A simulated run folder -> a bag with the topics and types a real PSM
    publishes: measured_js (position, velocity, the *simulated* effort) and
    jaw/measured_js, stamped with the simulated time."""
    from dvrk_dart.io.mcap_read import read_mcap
    from dvrk_dart.io.provenance import sha256_of, software_versions

    log = Path(run_dir) / "run.mcap"
    if not log.is_file():
        raise DvrkDartError(f"{run_dir}: no run.mcap (not a run folder)")
    try:
        record = read_mcap(log)
    except DvrkDartError:
        raise
    except Exception as exc:
        raise DvrkDartError(f"{log}: not a readable run log ({first_line(exc)})") from None
    if not len(record):
        raise DvrkDartError(f"{log}: the run has no samples")
    if np.isnan(record.effort_sim).all():
        raise DvrkDartError(f"{log}: the run has no simulated efforts (a kinematic run imposes poses only): no recording to export")
    for label, values in (("q", record.q), ("dq", record.dq), ("effort_sim", record.effort_sim)):
        bad = ~np.isfinite(values)
        if bad.any():
            k, j = np.argwhere(bad)[0]
            raise DvrkDartError(f"{log}: {label}{j + 1} is {values[k, j]} at t = {record.t[k]:.3f} s: nothing to export there")
    if storage == "ros1" and out.suffix != ".bag":
        raise DvrkDartError(f"--bag: a ROS 1 bag is a .bag file, not {out}")
    made_from = {"dvrk_dart.source_run": str(log.resolve()), "dvrk_dart.source_sha256": sha256_of(log),
                 **{f"dvrk_dart.{key}": str(value) for key, value in software_versions().items()}}
    return write_bag(out, arm_joint_states(model, arm, record.t, record.q, record.dq, record.effort_sim), storage, custom_data=made_from)
