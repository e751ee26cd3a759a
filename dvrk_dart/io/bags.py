"""Reading ROS bags (rosbags: ROS 2 bags in MCAP or sqlite3 storage, ROS 1
bags; no ROS installation needed).

In: a bag of a dVRK arm is a measured run. The arm's `measured_js` and (a PSM)
the jaw's `jaw/measured_js` (sensor_msgs/JointState, dVRK joint names and units,
as the arm's model card lists them in [dvrk_topics]) are read
by joint name, put on a uniform time grid by cubic interpolation of their header
stamps, and mapped to the identification model's coordinates (joints.py owns
the map). Writing them: `bag_writer.py`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.interpolate import CubicSpline

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.csv_run import say_once
from dvrk_dart.io.measured_run import CSV_COLUMNS, MeasuredRun, check_joint_ranges, sample_rate_hz
from dvrk_dart.io.outputs import MARKER
from dvrk_dart.io.signal import CUT_SAMPLES, MIN_ROWS
from dvrk_dart.model.description import DvrkTopics, PsmModel
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS
from dvrk_dart.model.model_file import load_model

JOINT_STATE = "sensor_msgs/msg/JointState"
#: a gap this long is missing data, not jitter: at 200 Hz it is 10 messages,
#: and the excitation moves up to ~0.08 rad in 50 ms, which no interpolation recovers
MAX_GAP_S = 0.05
#: file suffixes of bags that are single files (a rosbag2 folder has metadata.yaml)
BAG_SUFFIXES = (".mcap", ".db3", ".bag")
#: storage of the bags we write: rosbag2's default, and what Foxglove opens
STORAGES = ("mcap", "sqlite3", "ros1")
NS = 1_000_000_000
#: the dVRK 1.x topics of an arm's joints and of its jaw, in the arm's namespace (/dvrk/PSM1/...)
DVRK1_JOINTS, DVRK1_JAW = "state_joint_current", "state_jaw_current"


@dataclass(frozen=True)
class BagTopics:
    """Where an arm's joint states are in a bag, and the grid they are put on:
    the command's reading options (--arm, --topic, --jaw-topic, --rate); each
    default comes from the arm's [dvrk_topics] (`card`), passed with the arm."""

    arm: str | None = None  # default: the arm model's namespace (PSM1, MTML)
    topic: str | None = None  # default /<arm>/measured_js
    jaw_topic: str | None = None  # default /<arm>/jaw/measured_js
    rate_hz: float | None = None  # default: the reference data's rate (200 Hz)

    def namespace(self, card: DvrkTopics) -> str:
        return self.arm or card.namespace

    def joint_topic(self, card: DvrkTopics) -> str:
        return self.topic or f"/{self.namespace(card)}/measured_js"

    def jaw(self, card: DvrkTopics) -> str:
        """--jaw-topic, else the jaw of the arm's namespace (that of --topic when given; a dVRK 1.x
        state_joint_current's jaw is its state_jaw_current)."""
        if self.jaw_topic:
            return self.jaw_topic
        namespace = self.topic.rsplit("/", 1)[0] if self.topic else f"/{self.namespace(card)}"
        if self.topic and self.topic.endswith(f"/{DVRK1_JOINTS}"):
            return f"{namespace}/{DVRK1_JAW}"
        return f"{namespace}/jaw/measured_js"

    def wanted(self, card: DvrkTopics) -> list[tuple[str, tuple[str, ...]]]:
        """(topic, joint names) to read, in the order of q1..q7 (before the coupling)."""
        return [(self.joint_topic(card), card.arm_joints)] + ([(self.jaw(card), card.jaw_joints)] if card.jaw_joints else [])

    @property
    def rate(self) -> float:
        rate = sample_rate_hz() if self.rate_hz is None else float(self.rate_hz)
        if not np.isfinite(rate) or rate <= 0:
            raise DvrkDartError(f"--rate: {self.rate_hz!r} is not a positive rate (Hz)")
        return rate

    def record(self, card: DvrkTopics) -> dict:
        """What an output records of the options a bag was read with."""
        return {"arm": self.arm, "topic": self.joint_topic(card), "jaw_topic": self.jaw(card), "rate_hz": self.rate}


def is_bag(path: str | os.PathLike) -> bool:
    """A rosbag2 folder (metadata.yaml), or an .mcap/.db3/.bag file."""
    path = Path(path)
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix in BAG_SUFFIXES and path.is_file()


def _typestore(path: Path):
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC if path.suffix == ".bag" else Stores.ROS2_HUMBLE)


@dataclass
class TopicSamples:
    """One topic's messages: times (ns) and the named joints' values."""

    topic: str
    stamps_ns: np.ndarray
    position: np.ndarray  # (N, joints), dVRK units
    velocity: np.ndarray
    effort: np.ndarray
    receive_time: bool  # stamps are the bag's receive times (no header stamps)


def _other_families(card: DvrkTopics) -> dict[str, str]:
    """{namespace family: arm model} of the arm models other than `card`'s
    (a family is a namespace without the arm's number or side: MTM for MTML)."""
    from dvrk_dart.paths import MODELS_DIR

    current = card.namespace
    families = {}
    for folder in sorted(p for p in MODELS_DIR.iterdir() if (p / f"{p.name}.toml").is_file()):
        family = load_model(folder / f"{folder.name}.toml").dvrk_topics.namespace[:-1]
        if not current.startswith(family):
            families[family] = folder.name
    return families


def _other_arm_hint(present, card: DvrkTopics) -> str | None:
    """'add --arm-model X' when the bag holds the joint states of another arm model."""
    for family, model in _other_families(card).items():
        if any(t.startswith(f"/{family}") and t.endswith("/measured_js") for t in present):
            return f"the bag holds another arm's joints: add --arm-model {model}"
    return None


def check_arm_namespace(namespace: str | None, card: DvrkTopics) -> None:
    """--arm of a command that writes topics: not the namespace of another arm
    model (an MTM's servo_jp with the PSM's joints would drive the wrong arm)."""
    for family, model in _other_families(card).items():
        if namespace and namespace.startswith(family):
            raise DvrkDartError(f"--arm {namespace}: an arm of the {model} model, and these are the {card.namespace[:-1]}'s joints")


def first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    if type(exc).__name__ == "AnyReaderError" and text:  # rosbags' wrapper of every reader's error: its name says nothing
        return text[0]
    if isinstance(exc, UnicodeDecodeError):  # a ROS 1 reader decoding junk as a header
        return "its header is not a bag's"
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


def _is_run_recording(path: Path) -> bool:
    """A run.mcap that dvrk-dart wrote (its folder's marker lists it)."""
    marker = path.parent / MARKER
    return path.suffix == ".mcap" and marker.is_file() and path.name in marker.read_text(errors="replace")


def read_topics(path: Path, topics: BagTopics, card: DvrkTopics) -> tuple[TopicSamples, ...]:
    """The arm's (and a PSM jaw's) joint states, checked; one-line errors."""
    from rosbags.highlevel import AnyReader

    try:
        with AnyReader([path], default_typestore=_typestore(path)) as reader:
            present = reader.topics
            # (the two may be one topic: a recorder that puts the jaw in the arm's message)
            wanted = topics.wanted(card)
            if topics.jaw_topic is None and len(wanted) > 1 and wanted[0][0] in present and wanted[1][0] not in present:
                wanted = wanted[:1]  # a bag of the arm alone: the joints that need the jaw are not measured (load_bag_run)
            for topic in dict(wanted):
                if topic not in present:
                    listed = ", ".join(f"{t} ({i.msgtype})" for t, i in sorted(present.items())) or "none"
                    raise DvrkDartError(f"{path}: no topic {topic} (topics in the bag: {listed}); "
                                        f"{_other_arm_hint(present, card) or 'see --arm, --topic, --jaw-topic'}")
                msgtype = present[topic].msgtype
                if msgtype != JOINT_STATE:
                    raise DvrkDartError(f"{path}: topic {topic} has messages of type {msgtype}, expected {JOINT_STATE}")
                if present[topic].msgcount == 0:
                    raise DvrkDartError(f"{path}: topic {topic} has no messages")
            return tuple(_read_topic(reader, path, topic, names) for topic, names in wanted)
    except DvrkDartError:
        raise
    except Exception as exc:  # rosbags, mcap, sqlite3 and yaml each raise their own: one line for the user
        if _is_run_recording(path) and path.name == "run.mcap":
            raise DvrkDartError(f"{path}: a dvrk-dart run recording, not a ROS bag (`dvrk-dart export {path.parent} --bag BAG` "
                                "writes its joint states as one)") from None
        if _is_run_recording(path):  # force.mcap, ...: no joint states to export
            raise DvrkDartError(f"{path}: a dvrk-dart output ({path.name}), not a ROS bag of a measured run") from None
        raise DvrkDartError(f"{path}: not a readable bag ({first_line(exc)})") from None


def _read_topic(reader, path: Path, topic: str, names: tuple[str, ...]) -> TopicSamples:
    connections = [c for c in reader.connections if c.topic == topic]
    stamps, received, rows = [], [], {"position": [], "velocity": [], "effort": []}
    order, order_key = None, None
    bag_start = reader.start_time
    for connection, receive_ns, raw in reader.messages(connections=connections):
        msg = reader.deserialize(raw, connection.msgtype)
        stamps.append(msg.header.stamp.sec * NS + msg.header.stamp.nanosec)
        received.append(receive_ns)
        key = tuple(msg.name)
        if key != order_key:  # joints are matched by name, not by position in the message
            missing = [n for n in names if n not in key]
            if missing:
                raise DvrkDartError(f"{path}: topic {topic}: joint {missing[0]} missing from the message at t = {(receive_ns - bag_start) / NS:.3f} s into the bag (names: {', '.join(key) or 'none'})")
            order, order_key = [key.index(n) for n in names], key
        for field in rows:
            values = np.asarray(getattr(msg, field), dtype=float)
            if field == "effort" and len(values) == 0:  # JointState allows it: an effort not read (not measured, said)
                values = np.zeros(len(key))
            if len(values) != len(key):
                raise DvrkDartError(f"{path}: topic {topic}: {field} has {len(values)} values for {len(key)} joint names at t = {(receive_ns - bag_start) / NS:.3f} s into the bag")
            rows[field].append(values[order])
    arrays = {field: np.array(values, dtype=float).reshape(len(stamps), len(names)) for field, values in rows.items()}
    for field, values in arrays.items():
        bad = ~np.isfinite(values)
        if bad.any():
            k, j = np.argwhere(bad)[0]
            raise DvrkDartError(f"{path}: topic {topic}: {field} of {names[j]} is {values[k, j]} at t = {(received[k] - bag_start) / NS:.3f} s into the bag")
    stamps_ns = np.array(stamps, dtype=np.int64)
    receive_time = not stamps_ns.any()
    if receive_time:  # a recorder that leaves header stamps empty: the bag's receive times are all there is (said once read)
        stamps_ns = np.array(received, dtype=np.int64)
    return TopicSamples(topic, stamps_ns, arrays["position"], arrays["velocity"], arrays["effort"], receive_time)


def _check_times(path: Path, samples: TopicSamples) -> None:
    seconds = (samples.stamps_ns - samples.stamps_ns[0]) / NS
    steps = np.diff(seconds)
    unset = np.flatnonzero(samples.stamps_ns[1:] == 0) + 1  # (a first stamp of 0 is a simulated clock's start)
    if len(unset):  # a stamp left at zero among set ones read "backwards at t = -1700000000 s"
        raise DvrkDartError(f"{path}: topic {samples.topic}: message {unset[0] + 1} has no header stamp (0) among stamped ones")
    if (steps <= 0).any():
        k = int(np.argmax(steps <= 0))
        raise DvrkDartError(f"{path}: topic {samples.topic}: stamps go backwards (or repeat) at t = {seconds[k + 1]:.4f} s from its first message")
    if (steps > MAX_GAP_S).any():
        k = int(np.argmax(steps > MAX_GAP_S))
        raise DvrkDartError(
            f"{path}: topic {samples.topic}: gap of {steps[k] * 1e3:.0f} ms at t = {seconds[k]:.4f} s from its first message "
            f"(more than {MAX_GAP_S * 1e3:.0f} ms is missing data)"
        )


def _resample(samples: TopicSamples, start_ns: int, grid_s: np.ndarray) -> np.ndarray:
    """(len(grid), 3 * joints): position, velocity, effort on the grid (cubic)."""
    t = (samples.stamps_ns - start_ns) / NS
    values = np.hstack([samples.position, samples.velocity, samples.effort])
    # cubic: stamp jitter of +-1 ms moves the published errors by < 5e-4 (linear: 1.4e-3 on J4)
    return CubicSpline(t, values, axis=0)(grid_s)


def load_bag_run(path: str | os.PathLike, model: PsmModel, topics: BagTopics = BagTopics()) -> MeasuredRun:
    """A bag of `model`'s arm -> MeasuredRun (model coordinates, uniform grid), with one-line errors."""
    path = Path(path)
    rate = topics.rate
    if rate != sample_rate_hz():
        # upstream's filter, trim and first period are defined in samples at that rate
        raise DvrkDartError(f"--rate {rate:g}: measured runs are processed at {sample_rate_hz():g} Hz (the identification's processing); resample at that rate")
    read = read_topics(path, topics, model.dvrk_topics)
    if len({samples.receive_time for samples in read}) > 1:
        stamped = next(s for s in read if not s.receive_time)
        received = next(s for s in read if s.receive_time)
        raise DvrkDartError(f"{path}: {stamped.topic} has header stamps but {received.topic} only the bag's receive times: "
                            "two clocks cannot be aligned (record both with header stamps)")
    for samples in read:
        _check_times(path, samples)
    say_once([f"{path}: topic {s.topic} has no header stamps; using the bag's receive times" for s in read if s.receive_time])
    # the grid: multiples of the period on the bag's clock, so that a bag stamped
    # on a regular grid is sampled at its own stamps (no interpolation at all)
    first_ns = max(int(samples.stamps_ns[0]) for samples in read)
    if float(NS / rate).is_integer():  # integers: epoch stamps (~1.7e18 ns) are beyond float64's ns resolution
        period_ns = NS // int(rate)
        start_ns = -(-first_ns // period_ns) * period_ns
    else:
        start_ns = int(np.ceil(first_ns * rate / NS - 1e-9) * NS / rate)
    end_ns = min(int(samples.stamps_ns[-1]) for samples in read)
    span_s = (end_ns - start_ns) / NS
    n = int(np.floor(span_s * rate + 1e-9)) + 1 if end_ns >= start_ns else 0
    if n < MIN_ROWS:
        raise DvrkDartError(
            f"{path}: topics {' and '.join(s.topic for s in read)} overlap for {max(span_s, 0.0):.3f} s: "
            f"{max(n, 0)} samples at {rate:g} Hz, at least {MIN_ROWS} needed (the processing trims {CUT_SAMPLES} from each end)"
        )
    grid_s = np.arange(n) / rate
    values = [(_resample(samples, start_ns, grid_s), samples.position.shape[1]) for samples in read]
    dvrk = {  # each topic's values hold its position, velocity and effort columns side by side
        field: np.hstack([v[:, i * k : (i + 1) * k] for v, k in values])
        for i, field in enumerate(("position", "velocity", "effort"))
    }
    values, measured = _in_model_coordinates(dvrk, model, path, topics)
    check_joint_ranges(values[:, :N_JOINTS], path, model)
    data = pd.DataFrame(values, columns=CSV_COLUMNS)
    data.insert(0, "t", grid_s)
    return MeasuredRun(path=path, data=data, model=model, measured=measured)


def _in_model_coordinates(dvrk: dict, model: PsmModel, path: Path, topics: BagTopics) -> tuple[np.ndarray, tuple[str, ...]]:
    """The dVRK's position, velocity and effort -> (N, 21) in the model's
    coordinates, and the joints measured, the others said: without the jaw's
    topic, those whose coordinate needs the jaw are zeros; a joint whose effort
    never changes (not read: zeros, or an empty effort field) is not measured,
    its positions kept, and a coupled one takes its partners with it (as in a CSV)."""
    logged = np.arange(N_JOINTS) < dvrk["position"].shape[1]  # the jaw's columns come last (BagTopics.wanted)
    padded = {field: np.pad(values, ((0, 0), (0, N_JOINTS - values.shape[1]))) for field, values in dvrk.items()}
    motor_map = model.motor_map
    values = np.hstack([motor_map.positions_to_model(padded["position"]), motor_map.positions_to_model(padded["velocity"]),
                        motor_map.efforts_to_model(padded["effort"])])
    determined = motor_map.determined_by(logged)
    values[:, np.tile(~determined, 3)] = 0.0
    notes = []
    if not determined.all():
        unmeasured = ", ".join(name for name, known in zip(JOINT_NAMES, determined) if not known)
        notes.append(f"{path}: no topic {topics.jaw(model.dvrk_topics)}: {unmeasured} not measured (each coupled coordinate mixes "
                     "the jaw; --jaw-topic names another)")
    read = motor_map.determined_by(logged & (np.ptp(padded["effort"], axis=0) > 0.0)) & determined
    if (determined & ~read).any():
        names = ", ".join(name for name, r, d in zip(JOINT_NAMES, read, determined) if d and not r)
        notes.append(f"{path}: {names}: the effort never changes (or a coupled partner's does not): read as not recorded")
    if not read.any():
        raise DvrkDartError(f"{path}: no effort changes: no effort was recorded")
    values[:, 2 * N_JOINTS:][:, ~read] = 0.0
    say_once(notes)
    return values, tuple(name for name, known in zip(JOINT_NAMES, read) if known)
