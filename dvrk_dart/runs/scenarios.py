"""Scenarios as data: `pipelines/scenarios/<name>.toml`, checked on load, and
the Cartesian reference paths they describe."""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.reference_data import RUNS
from dvrk_dart.model.description import DEFAULT_MODEL_FILE, resolve_arm_model
from dvrk_dart.model.model_file import load_model
from dvrk_dart.model.joints import N_JOINTS
from dvrk_dart.paths import PIPELINES_DIR
from dvrk_dart.sim.config import COUNTERWEIGHT_VARIANTS, MODES

SCENARIOS_DIR = PIPELINES_DIR / "scenarios"

_TOP_KEYS = {"name", "kind", "duration_s", "modes", "counterweights", "start_pose", "path", "measured", "description", "dynamics", "arm_model"}
#: the simulated arms a scenario may ask for (runs.config.RunConfig.dynamics), or a diagnosis.json
DYNAMICS_CHOICES = ("inertial", "identified")
_PATH_KEYS = {
    "line": {"type", "length_m", "direction"},
    "spiral": {"type", "radius_m", "height_m", "radius_frequency_hz", "height_frequency_hz"},
}


@dataclass(frozen=True)
class CartesianPath:
    """A tool-tip position path with a constant orientation (the start's)."""

    type: str
    params: dict
    start_position: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def position_velocity_acceleration(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        p0 = self.start_position
        if self.type == "line":
            speed = self.params["length_m"] / self.duration_s
            u = np.asarray(self.params["direction"], dtype=float)
            u = u / np.abs(u).max()  # first: the norm of 1e300 or 1e-300 components is not a float
            u = u / np.linalg.norm(u)
            return p0 + speed * t * u, speed * u, np.zeros(3)
        A, h = self.params["radius_m"], self.params["height_m"]
        wA = 2 * math.pi * self.params["radius_frequency_hz"]
        wh = 2 * math.pi * self.params["height_frequency_hz"]
        centre = p0 - np.array([A, 0.0, h])  # r_d(0) = start: no initial jump
        cA, sA, ch, sh = math.cos(wA * t), math.sin(wA * t), math.cos(wh * t), math.sin(wh * t)
        position = centre + np.array([A * cA, A * sA, h * ch])
        velocity = np.array([-A * wA * sA, A * wA * cA, -h * wh * sh])
        acceleration = np.array([-A * wA**2 * cA, -A * wA**2 * sA, -h * wh**2 * ch])
        return position, velocity, acceleration

    @property
    def duration_s(self) -> float:
        return float(self.params["duration_s"])


@dataclass(frozen=True)
class Scenario:
    name: str
    kind: str  # "cartesian" | "replay"
    modes: tuple[str, ...]
    counterweights: tuple[str, ...]
    duration_s: float | None = None
    start_pose: np.ndarray | None = None
    path: dict | None = None
    measured: str | None = None
    source: Path | None = None
    dynamics: str = "inertial"  # the simulated arm, unless a run overrides it
    arm_model: str | None = None  # the arm (models/<arm>/), None: the command's (--arm-model)

    def cartesian_path(self, start_position: np.ndarray) -> CartesianPath:
        params = dict(self.path or {})
        params["duration_s"] = self.duration_s
        return CartesianPath(type=params["type"], params=params, start_position=np.asarray(start_position, dtype=float))

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "kind": self.kind,
            "modes": list(self.modes),
            "counterweights": list(self.counterweights),
            "duration_s": self.duration_s,
            "start_pose": None if self.start_pose is None else self.start_pose.tolist(),
            "path": self.path,
            "measured": self.measured,
            "dynamics": self.dynamics,
            "arm_model": self.arm_model,
        }


def _fail(path: Path, message: str) -> None:
    raise DvrkDartError(f"{path}: {message}")


def _positive(path: Path, table: dict, key: str, where: str) -> float:
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        _fail(path, f"{where}{key} must be a positive number, got {value!r}")
    return float(value)


#: the longest run (s): an hour of simulated time at 1 kHz is 3.6 M steps, whose
#: logs still fit in memory; longer runs belong in several files
MAX_DURATION_S = 3600.0


def _duration(path: Path, raw: dict) -> float:
    duration = _positive(path, raw, "duration_s", "")
    if duration > MAX_DURATION_S:
        _fail(path, f"duration_s {duration:g} s is above {MAX_DURATION_S:g} s (an hour: longer runs belong in several files)")
    return duration


def _string_list(path: Path, raw: dict, key: str, allowed: tuple[str, ...], default: tuple[str, ...] | None) -> tuple[str, ...]:
    value = raw.get(key, default)
    if not isinstance(value, (list, tuple)) or not value or any(not isinstance(v, str) or v not in allowed for v in value):
        _fail(path, f"{key} must be a non-empty list of {', '.join(allowed)}, got {value!r}")
    return tuple(value)


def _vector(path: Path, table: dict, key: str, size: int, where: str = "") -> np.ndarray:
    value = table.get(key)
    if (not isinstance(value, list) or len(value) != size
            or any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) for v in value)):
        _fail(path, f"{where}{key} must be a list of {size} finite numbers, got {value!r}")
    return np.asarray(value, dtype=float)


def _read_toml(path: Path) -> dict:
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DvrkDartError(f"{path}: scenario file not found") from None
    except IsADirectoryError:
        raise DvrkDartError(f"{path}: is a folder, not a scenario file") from None
    except UnicodeDecodeError:
        raise DvrkDartError(f"{path}: not UTF-8 text") from None
    except tomllib.TOMLDecodeError as exc:
        raise DvrkDartError(f"{path}: not valid TOML ({exc})") from None


def load_scenario_file(path: Path) -> Scenario:
    """A scenario file checked against its schema: types, units (SI), ranges."""
    raw = _read_toml(path)
    unknown = set(raw) - _TOP_KEYS
    if unknown:
        _fail(path, f"unknown key(s) {', '.join(sorted(unknown))}")
    name = raw.get("name", path.stem)
    if not (isinstance(name, str) and re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_.-]*", name)):  # it names the run's folder and files
        _fail(path, f"name must be letters, digits, '_', '-' and '.' (it names the run's folder), got {name!r}")
    kind = raw.get("kind")
    if kind not in ("cartesian", "replay"):
        _fail(path, f"kind must be 'cartesian' or 'replay', got {kind!r}")
    modes = _string_list(path, raw, "modes", MODES, None)
    counterweights = _string_list(path, raw, "counterweights", COUNTERWEIGHT_VARIANTS, ("on",))
    if "description" in raw and not isinstance(raw["description"], str):
        _fail(path, "description must be a string")
    dynamics = raw.get("dynamics", "inertial")
    if not isinstance(dynamics, str) or (dynamics not in DYNAMICS_CHOICES and not dynamics.endswith(".json")):
        _fail(path, f"dynamics must be one of {', '.join(DYNAMICS_CHOICES)} or a diagnosis .json file, got {dynamics!r}")
    if dynamics.endswith(".json"):  # relative to the scenario file
        dynamics = str((path.parent / dynamics).resolve())
    arm_model = raw.get("arm_model")
    if arm_model is not None and not isinstance(arm_model, str):
        _fail(path, f"arm_model must be an arm's name (psm, mtm), got {arm_model!r}")
    if arm_model is not None:
        try:
            resolve_arm_model(arm_model)
        except DvrkDartError as exc:  # its words name the option; the value is the file's
            _fail(path, f"arm_model: {str(exc).removeprefix('--arm-model ')}")
    if kind == "replay":
        if not isinstance(raw.get("measured"), str) or not raw["measured"]:
            _fail(path, "a replay needs measured = '<run name or file>'")
        duration = _duration(path, raw) if "duration_s" in raw else None
        measured = raw["measured"]
        if Path(measured).suffix and not Path(measured).is_absolute():  # a file, relative to the scenario file (a run name has no suffix)
            measured = str(path.parent / measured)
        if measured not in RUNS and not Path(measured).exists():
            _fail(path, f"measured = {raw['measured']!r}: not a reference run ({', '.join(RUNS)}) nor a file")
        return Scenario(name, kind, modes, counterweights, duration, measured=measured, source=path, dynamics=dynamics,
                        arm_model=arm_model)
    duration = _duration(path, raw)
    start = _vector(path, raw, "start_pose", N_JOINTS)
    model = load_model(resolve_arm_model(arm_model) if arm_model else DEFAULT_MODEL_FILE)
    lower, upper = model.joint_lower, model.joint_upper
    for j in np.flatnonzero((start < lower) | (start > upper)):
        _fail(path, f"start_pose: q{j + 1} = {float(start[j])!r} outside the joint range [{float(lower[j])!r}, {float(upper[j])!r}]")
    path_table = raw.get("path")
    if not isinstance(path_table, dict) or path_table.get("type") not in _PATH_KEYS:
        _fail(path, f"[path] must have type one of {sorted(_PATH_KEYS)}")
    expected = _PATH_KEYS[path_table["type"]]
    if set(path_table) != expected:
        _fail(path, f"[path] of type {path_table['type']} takes exactly {sorted(expected)}, got {sorted(path_table)}")
    for key in expected - {"type", "direction"}:
        _positive(path, path_table, key, "path.")
    if "direction" in path_table and not np.any(_vector(path, path_table, "direction", 3, "path.") != 0):
        _fail(path, "path.direction must be a non-zero 3-vector")
    return Scenario(name, kind, modes, counterweights, duration, start, dict(path_table), source=path, dynamics=dynamics,
                    arm_model=arm_model)


def available_scenarios() -> list[str]:
    return sorted(p.stem for p in SCENARIOS_DIR.glob("*.toml"))


def load_scenario(name_or_path: str) -> Scenario:
    """A scenario by name (pipelines/scenarios/<name>.toml) or file path."""
    path = Path(name_or_path)
    if path.suffix == ".toml":
        return load_scenario_file(path)
    candidate = SCENARIOS_DIR / f"{name_or_path}.toml"
    if not candidate.is_file():
        raise DvrkDartError(f"unknown scenario '{name_or_path}' (known: {', '.join(available_scenarios())})")
    return load_scenario_file(candidate)
