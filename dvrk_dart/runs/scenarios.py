"""Scenarios as data: `pipelines/scenarios/<name>.toml`, checked on load, and
the Cartesian reference paths they describe."""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.model.joints import N_JOINTS
from dvrk_dart.sim.config import COUNTERWEIGHT_VARIANTS, MODES
from dvrk_dart.paths import PIPELINES_DIR

SCENARIOS_DIR = PIPELINES_DIR / "scenarios"

_TOP_KEYS = {"name", "kind", "duration_s", "modes", "counterweights", "start_pose", "path", "measured", "description"}
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
        }


def _fail(path: Path, message: str) -> None:
    raise DvrkDartError(f"{path}: {message}")


def _positive(path: Path, table: dict, key: str, where: str) -> float:
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        _fail(path, f"{where}{key} must be a positive number, got {value!r}")
    return float(value)


def load_scenario_file(path: Path) -> Scenario:
    try:
        raw = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise DvrkDartError(f"{path}: scenario file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise DvrkDartError(f"{path}: not valid TOML ({exc})") from None
    unknown = set(raw) - _TOP_KEYS
    if unknown:
        _fail(path, f"unknown key(s) {', '.join(sorted(unknown))}")
    kind = raw.get("kind")
    if kind not in ("cartesian", "replay"):
        _fail(path, f"kind must be 'cartesian' or 'replay', got {kind!r}")
    modes = tuple(raw.get("modes", ()))
    if not modes or any(m not in MODES for m in modes):
        _fail(path, f"modes must be a non-empty subset of {MODES}, got {list(modes)}")
    counterweights = tuple(raw.get("counterweights", ("on",)))
    if any(c not in COUNTERWEIGHT_VARIANTS for c in counterweights):
        _fail(path, f"counterweights must be a subset of {COUNTERWEIGHT_VARIANTS}, got {list(counterweights)}")
    if kind == "replay":
        if not isinstance(raw.get("measured"), str):
            _fail(path, "a replay needs measured = '<run name or file>'")
        duration = raw.get("duration_s")
        if duration is not None:
            duration = _positive(path, raw, "duration_s", "")
        return Scenario(raw.get("name", path.stem), kind, modes, counterweights, duration, measured=raw["measured"], source=path)
    duration = _positive(path, raw, "duration_s", "")
    start = np.asarray(raw.get("start_pose", []), dtype=float)
    if start.shape != (N_JOINTS,) or not np.all(np.isfinite(start)):
        _fail(path, f"start_pose must hold {N_JOINTS} finite numbers")
    path_table = raw.get("path")
    if not isinstance(path_table, dict) or path_table.get("type") not in _PATH_KEYS:
        _fail(path, f"[path] must have type one of {sorted(_PATH_KEYS)}")
    expected = _PATH_KEYS[path_table["type"]]
    if set(path_table) != expected:
        _fail(path, f"[path] of type {path_table['type']} takes exactly {sorted(expected)}, got {sorted(path_table)}")
    for key in expected - {"type", "direction"}:
        _positive(path, path_table, key, "path.")
    if "direction" in path_table:
        direction = np.asarray(path_table["direction"], dtype=float)
        if direction.shape != (3,) or not np.linalg.norm(direction) > 0:
            _fail(path, "path.direction must be a non-zero 3-vector")
    return Scenario(raw.get("name", path.stem), kind, modes, counterweights, duration, start, dict(path_table), source=path)


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
