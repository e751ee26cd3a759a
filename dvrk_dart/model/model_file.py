"""Reading an arm's model description file (`models/psm/psm.toml`,
`models/mtm/mtm.toml`) into a `PsmModel` (model/description.py), with
one-line errors naming the file and the entry. The single reader of the file."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.model.card_checks import check_model_values
from dvrk_dart.model.description import DvrkTopics, ForcePoint, LoopClosure, PsmModel, SessionPayloadReading, UpstreamProcessing
from dvrk_dart.model.dh import DHFrame, LinearExpr, Link
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS


class _ExpressionReader:
    """Turns {name = coefficient} tables into LinearExpr, naming the offending entry."""

    def __init__(self, path: Path, constants: dict[str, float]):
        self.path = path
        self.constants = constants
        self.model_angles: dict[str, LinearExpr] = {}

    def read(self, table: object, where: str) -> LinearExpr:
        if not isinstance(table, dict):
            raise DvrkDartError(f"{self.path}: {where} must be a table {{name = coefficient}}")
        expr = LinearExpr.constant(0.0)
        for name, coeff in table.items():
            if not isinstance(coeff, (int, float)) or not math.isfinite(coeff):
                raise DvrkDartError(f"{self.path}: {where}.{name} must be a finite number")
            expr = expr + self._term(name, where).scaled(float(coeff))
        return expr

    def _term(self, name: str, where: str) -> LinearExpr:
        if name == "pi":
            return LinearExpr.constant(math.pi)
        if name in self.constants:
            return LinearExpr.constant(self.constants[name])
        if name in JOINT_NAMES:
            coeffs = np.zeros(N_JOINTS)
            coeffs[JOINT_NAMES.index(name)] = 1.0
            return LinearExpr(coeffs, 0.0)
        if name in self.model_angles:
            return self.model_angles[name]
        raise DvrkDartError(f"{self.path}: {where} uses unknown name '{name}'")


def _require(table: dict, key: str, path: Path, where: str):
    if key not in table:
        raise DvrkDartError(f"{path}: {where} is missing '{key}'")
    return table[key]


DIAGNOSIS_BASES = ("inertial", "identified")
#: what an elastic joint of [diagnosis] elastic may be
ELASTIC_KINDS = ("cable_elasticity", "torsion_spring")


def _force_point(raw: dict, path: Path, links: dict) -> ForcePoint | None:
    table = raw.get("force_point")
    if table is None:
        return None
    name = str(_require(table, "link", path, "[force_point]"))
    keys = [k for k, link in links.items() if link.name == name]
    if not keys:
        raise DvrkDartError(f"{path}: [force_point] link '{name}' is not a link of the model")
    names = list(_require(table, "joints", path, "[force_point]"))
    unknown = [str(j) for j in names if j not in JOINT_NAMES]
    if unknown:
        raise DvrkDartError(f"{path}: [force_point] joints: unknown {', '.join(unknown)} (known: {', '.join(JOINT_NAMES)})")
    lever = _floats(_require(table, "min_lever_m", path, "[force_point]"), path, "[force_point] min_lever_m")
    return ForcePoint(keys[0], str(table.get("point", name)), tuple(JOINT_NAMES.index(j) for j in names), float(lever))


def _diagnosis_base(raw: dict, path: Path) -> str:
    base = raw.get("diagnosis", {}).get("base", "inertial")
    if base not in DIAGNOSIS_BASES:
        raise DvrkDartError(f"{path}: [diagnosis] base must be one of {', '.join(DIAGNOSIS_BASES)}, not {base!r}")
    return base


def _diagnosis_joints(raw: dict, path: Path) -> tuple[tuple[tuple[str, str], ...], tuple[str, ...]]:
    """[diagnosis] elastic (joint -> its elasticity's kind) and position_friction (joints): the arm's own candidates."""
    table = raw.get("diagnosis", {})
    elastic, position_friction = table.get("elastic", {}), table.get("position_friction", [])
    if not isinstance(elastic, dict) or not isinstance(position_friction, list):
        raise DvrkDartError(f"{path}: [diagnosis] elastic is a table (joint = kind), position_friction a list of joints")
    if unknown := [str(j) for j in [*elastic, *position_friction] if j not in JOINT_NAMES]:
        raise DvrkDartError(f"{path}: [diagnosis]: unknown joint {', '.join(unknown)} (known: {', '.join(JOINT_NAMES)})")
    if len(set(position_friction)) < len(position_friction):
        raise DvrkDartError(f"{path}: [diagnosis] position_friction names a joint twice: {position_friction}")
    if wrong := [f"{j} = {k!r}" for j, k in elastic.items() if k not in ELASTIC_KINDS]:
        raise DvrkDartError(f"{path}: [diagnosis] elastic: {', '.join(wrong)} (a kind is one of {', '.join(ELASTIC_KINDS)})")
    return tuple((str(j), str(k)) for j, k in elastic.items()), tuple(str(j) for j in position_friction)


def _frame_words(raw: dict, path: Path) -> str:
    words = raw.get("diagnosis", {}).get("frame_words", "")
    if not isinstance(words, str):
        raise DvrkDartError(f"{path}: [diagnosis] frame_words is a text (the base frame at q = 0 in words), not {words!r}")
    return words


def _upstream_processing(raw: dict, path: Path) -> UpstreamProcessing:
    table = _require(raw, "processing", path, "file")
    try:
        return UpstreamProcessing(float(table["cutoff_parameter_hz"]), int(table["first_period_samples"]), float(table["filter_rate_hz"]))
    except (KeyError, TypeError, ValueError):
        raise DvrkDartError(f"{path}: [processing] needs cutoff_parameter_hz and filter_rate_hz (numbers) and first_period_samples "
                            "(an integer)") from None


def load_model(path: Path | str) -> PsmModel:
    """Read and check an arm's model description file."""
    path = Path(path)
    raw = _read_toml(path)
    try:
        return _model(raw, path)
    except (TypeError, ValueError) as exc:  # text where a number goes ("abc" for a length): the file's fault, said in one line
        raise DvrkDartError(f"{path}: a value of the wrong type ({exc})") from None


#: the tables and entries of a model card (a misspelt table, [[linkz]], was read as missing links further on)
CARD_KEYS = ("name", "default_parameters", "groups", "joint_words", "gravity_m_s2", "constants", "model_angles", "links",
             "loop_closures", "tool_tip", "counterweight", "joint_limits", "dvrk_coupling", "dvrk_velocity_limits", "dvrk_topics",
             "parameter_checks", "processing", "sessions", "controllers", "diagnosis", "force_point")


def _model(raw: dict, path: Path) -> PsmModel:
    if unknown := sorted(set(raw) - set(CARD_KEYS)):
        raise DvrkDartError(f"{path}: unknown {', '.join(map(repr, unknown))} (a model card holds {', '.join(CARD_KEYS)})")
    constants = {k: float(v) for k, v in _require(raw, "constants", path, "file").items()}
    reader = _ExpressionReader(path, constants)
    for name, table in raw.get("model_angles", {}).items():
        reader.model_angles[name] = reader.read(table, f"model_angles.{name}")
    groups = tuple(_require(raw, "groups", path, "file"))
    links = _links(raw, path, reader, groups)
    cw = raw.get("counterweight")
    if cw is not None and int(cw["link"]) not in links:
        raise DvrkDartError(f"{path}: [counterweight] names unknown link {cw['link']}")
    limits = _require(raw, "joint_limits", path, "file")
    coupling = _require(raw, "dvrk_coupling", path, "file")
    checks = raw.get("parameter_checks", {})
    elastic, position_friction = _diagnosis_joints(raw, path)
    model = PsmModel(
        name=raw.get("name", path.stem),
        source=path,
        constants=constants,
        gravity=_floats(raw.get("gravity_m_s2", [0.0, 0.0, -9.81]), path, "gravity_m_s2"),
        default_parameters=raw.get("default_parameters", "params.json"),
        links=links,
        tool_tip=_tool_tip(raw, path, reader),
        loop_closures=_loop_closures(raw, path, reader, links),
        counterweight_link=int(cw["link"]) if cw is not None else None,
        counterweight_ratio=float(cw.get("ratio", 1.0)) if cw is not None else 0.0,
        joint_lower=_floats(_require(limits, "lower", path, "[joint_limits]"), path, "[joint_limits] lower"),
        joint_upper=_floats(_require(limits, "upper", path, "[joint_limits]"), path, "[joint_limits] upper"),
        dvrk_coupling_matrix=_floats(_require(coupling, "matrix", path, "[dvrk_coupling]"), path, "[dvrk_coupling] matrix"),
        dvrk_coupling_columns=_coupling_columns(coupling, path),
        dvrk_velocity_limits=_floats(raw["dvrk_velocity_limits"].get("upper"), path, "[dvrk_velocity_limits] upper") if "dvrk_velocity_limits" in raw else None,
        inertia_tolerance=float(checks.get("inertia_tolerance_kg_m2", 0.0)),
        max_link_mass_kg=float(checks.get("max_link_mass_kg", float("inf"))),
        max_com_distance_m=float(checks.get("max_com_distance_m", float("inf"))),
        identification_mass_bounds_kg=_mass_bounds(checks, path, links),
        model_angles=dict(reader.model_angles),
        session_offset_joints=_session_offset_joints(raw, path),
        session_repeat_pair=_session_repeat_pair(raw, path),
        session_constant_change=_session_constant_change(raw, path),
        session_payload_reading=_session_payload_reading(raw, path),
        controller_gains=dict(raw.get("controllers", {})),
        groups=groups,
        joint_words=str(raw.get("joint_words", "")),
        processing=_upstream_processing(raw, path),
        dvrk_topics=_dvrk_topics(raw, path),
        project_unphysical_bodies=bool(checks.get("project_unphysical_bodies", False)),
        diagnosis_base=_diagnosis_base(raw, path),
        elastic_joints=elastic, position_friction_joints=position_friction, frame_words=_frame_words(raw, path),
        force_point=_force_point(raw, path, links),
    )
    check_model_values(model, cw)
    return model


def _floats(values, path: Path, entry: str) -> np.ndarray:
    """An entry's numbers as an array (its shape is check_model_values's)."""
    try:
        return np.array(values, dtype=float)
    except (TypeError, ValueError):
        raise DvrkDartError(f"{path}: {entry} must be numbers, not {values!r}") from None


def _mass_bounds(checks: dict, path: Path, links: dict) -> dict[int, float]:
    """[parameter_checks] identification_mass_bounds_kg: {link key = kg}."""
    bounds = {}
    for key, value in checks.get("identification_mass_bounds_kg", {}).items():
        if not (str(key).isdigit() and int(key) in links and isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise DvrkDartError(f"{path}: [parameter_checks] identification_mass_bounds_kg: {key} = {value!r}: "
                                "a link's key and its largest mass (kg, positive)")
        bounds[int(key)] = float(value)
    return bounds


def _read_toml(path: Path) -> dict:
    try:
        return tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise DvrkDartError(f"{path}: model file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise DvrkDartError(f"{path}: not valid TOML ({exc})") from None


def _unique_name(entry: dict, links: dict, path: Path, where: str) -> str:
    name = _require(entry, "name", path, where)
    if any(link.name == name for link in links.values()):
        raise DvrkDartError(f"{path}: {where} is named '{name}' like another link")
    return name


def _flag(entry: dict, flag: str, default: bool, path: Path, where: str) -> bool:
    """A link's true/false entry ('yes' was read as true)."""
    value = entry.get(flag, default)
    if not isinstance(value, bool):
        raise DvrkDartError(f"{path}: {where}.{flag} must be true or false, not {value!r}")
    return value


def _links(raw: dict, path: Path, reader: _ExpressionReader, groups: tuple[str, ...]) -> dict[int, Link]:
    """[[links]], parents before children, each in one of the file's groups."""
    links: dict[int, Link] = {}
    for entry in _require(raw, "links", path, "file"):
        key = int(_require(entry, "key", path, "a link"))
        where = f"links[key={key}]"
        if key in links:
            raise DvrkDartError(f"{path}: {where} given twice")
        parent = int(_require(entry, "parent", path, where))
        if parent != 0 and parent not in links:
            raise DvrkDartError(f"{path}: {where} has parent {parent} not defined before it")
        group = _require(entry, "group", path, where)
        if group not in groups:
            raise DvrkDartError(f"{path}: {where} has group '{group}', expected one of {', '.join(groups)} (the file's groups)")
        link = Link(
            parent=parent,
            **{k: reader.read(entry.get(k, {}), f"{where}.{k}") for k in ("a", "alpha", "d", "theta")},
            key=key,
            name=_unique_name(entry, links, path, where),
            group=group,
            **{flag: _flag(entry, flag, flag == "body", path, where) for flag in ("body", "inertia", "friction", "motor_inertia", "spring")},
            spring_linkage={k: float(v) for k, v in entry["spring_linkage"].items()} if "spring_linkage" in entry else None,
            cable_polynomial=tuple(float(c) for c in entry["cable_polynomial"]) if "cable_polynomial" in entry else None,
        )
        _ = link.joint_type  # raises on a link with two variables
        links[key] = link
    return links


def _tool_tip(raw: dict, path: Path, reader: _ExpressionReader) -> DHFrame:
    tip = _require(raw, "tool_tip", path, "file")
    return DHFrame(parent=int(tip["parent"]), **{k: reader.read(tip.get(k, {}), f"tool_tip.{k}") for k in ("a", "alpha", "d", "theta")})


def _loop_closures(raw: dict, path: Path, reader: _ExpressionReader, links: dict[int, Link]) -> tuple[LoopClosure, ...]:
    closures = tuple(
        LoopClosure(
            name=c["name"],
            link=int(c["link"]),
            other=int(c["other"]),
            point_in_link=np.array(
                [float(reader.read(c["point"].get(ax, {}), f"loop_closures.{c['name']}.point.{ax}").const) for ax in "xyz"]
            ),
        )
        for c in raw.get("loop_closures", [])
    )
    for c in closures:
        for k in (c.link, c.other):
            if k not in links:
                raise DvrkDartError(f"{path}: loop closure '{c.name}' names unknown link {k}")
    return closures


def _coupling_columns(coupling: dict, path: Path) -> tuple[int, ...]:
    columns = tuple(int(c) for c in _require(coupling, "columns", path, "[dvrk_coupling]"))
    if any(not 0 <= c < N_JOINTS for c in columns):
        raise DvrkDartError(f"{path}: [dvrk_coupling] columns must be 0..{N_JOINTS - 1} (0 is q1)")
    return columns


def _dvrk_topics(raw: dict, path: Path) -> DvrkTopics:
    table = _require(raw, "dvrk_topics", path, "file")
    topics = DvrkTopics(str(_require(table, "namespace", path, "[dvrk_topics]")), tuple(_require(table, "arm_joints", path, "[dvrk_topics]")),
                        tuple(table.get("jaw_joints", ())))
    if len(topics.joint_names) != N_JOINTS:
        raise DvrkDartError(f"{path}: [dvrk_topics] names {len(topics.joint_names)} joints, the model has {N_JOINTS}")
    return topics


def _session_repeat_pair(raw: dict, path: Path) -> tuple[str, ...]:
    """[sessions] repeat_pair: two reference files (manifest names), or none."""
    pair = tuple(str(name) for name in raw.get("sessions", {}).get("repeat_pair", ()))
    if len(pair) not in (0, 2):
        raise DvrkDartError(f"{path}: [sessions] repeat_pair names {len(pair)} files, expected 2")
    return pair


def _session_offset_joints(raw: dict, path: Path) -> tuple[str, ...] | None:
    """[sessions] offset_joints: joint names (q1..q7) whose constant effort moves between sessions."""
    if "sessions" not in raw:
        return None
    names = tuple(raw["sessions"].get("offset_joints", ()))
    unknown = [n for n in names if n not in JOINT_NAMES]
    if unknown:
        raise DvrkDartError(f"{path}: [sessions] offset_joints: unknown joint(s) {', '.join(map(str, unknown))} (known: {', '.join(JOINT_NAMES)})")
    return names


def _session_constant_change(raw: dict, path: Path) -> tuple[float, ...] | None:
    """[sessions] constant_change: per joint (q1..q7), how much a joint's constant effort moved between the
    repeat pair's sessions (N·m, N), or none."""
    values = raw.get("sessions", {}).get("constant_change")
    if values is None:
        return None
    if len(values) != len(JOINT_NAMES) or not all(isinstance(v, (int, float)) and v >= 0 for v in values):
        raise DvrkDartError(f"{path}: [sessions] constant_change: {len(JOINT_NAMES)} non-negative numbers expected (q1..q7)")
    return tuple(float(v) for v in values)


def _session_payload_reading(raw: dict, path: Path) -> SessionPayloadReading | None:
    """[sessions] payload_reading: {q1_effort_at_q0, q1_slope_at_q0}, non-negative, or none."""
    table = raw.get("sessions", {}).get("payload_reading")
    if table is None:
        return None
    keys = ("q1_effort_at_q0", "q1_slope_at_q0")
    if not isinstance(table, dict) or set(table) != set(keys) or not all(isinstance(table[k], (int, float)) and table[k] >= 0 for k in keys):
        raise DvrkDartError(f"{path}: [sessions] payload_reading: {{{', '.join(f'{k} = a non-negative number' for k in keys)}}} expected")
    return SessionPayloadReading(*(float(table[k]) for k in keys))
