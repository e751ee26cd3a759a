"""The verdicts (pipelines/checks.toml: thresholds on the analysis tables) and
the comparison with published numbers (pipelines/published.toml)."""

from __future__ import annotations

import decimal
import math
import os
import tomllib
from pathlib import Path

import pandas as pd

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.metrics import REGIME_ALL
from dvrk_dart.paths import PIPELINES_DIR

CHECKS_FILE = PIPELINES_DIR / "checks.toml"
PUBLISHED_FILE = PIPELINES_DIR / "published.toml"


def _load_toml(path: Path, what: str) -> dict:
    try:
        return tomllib.loads(Path(path).read_text())
    except FileNotFoundError:
        raise DvrkDartError(f"{path}: {what} file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise DvrkDartError(f"{path}: {exc}") from None


def load_checks(path: str | os.PathLike = CHECKS_FILE) -> list[dict]:
    checks = _load_toml(Path(path), "checks").get("checks", [])
    required = {"id", "title", "quantity", "runs", "components", "operator", "threshold", "unit"}
    for check in checks:
        missing = required - set(check)
        if missing:
            raise DvrkDartError(f"{path}: check {check.get('id', '?')} lacks {', '.join(sorted(missing))}")
        if check["operator"] not in OPERATORS:
            raise DvrkDartError(f"{path}: check {check['id']}: operator must be one of {', '.join(OPERATORS)}")
    return checks


def load_published(path: str | os.PathLike = PUBLISHED_FILE) -> dict:
    data = _load_toml(Path(path), "published numbers")
    for entry in data.get("published", []):
        if entry.get("source") not in data.get("sources", {}):
            raise DvrkDartError(f"{path}: {entry.get('id')}: unknown source '{entry.get('source')}'")
        if entry.get("kind", KIND_ERROR) not in (KIND_ERROR, KIND_EFFECT):
            raise DvrkDartError(f"{path}: {entry['id']}: kind must be '{KIND_ERROR}' or '{KIND_EFFECT}'")
        if len(entry["values"]) != len(entry["components"]):
            raise DvrkDartError(f"{path}: {entry['id']}: {len(entry['values'])} values for {len(entry['components'])} components")
        for target in entry.get("compare", []):
            if target.get("goal", "smaller") not in GOALS:
                raise DvrkDartError(f"{path}: {entry['id']}: compare goal must be one of {', '.join(GOALS)}")
    return data


#: operator -> (test of a value against the threshold, the worst of several values)
OPERATORS = {"<=": (lambda v, limit: v <= limit, max), ">": (lambda v, limit: v > limit, min)}

CHECK_COLUMNS = ["check", "title", "run", "component", "value", "operator", "threshold", "unit", "status"]
STATUS_PASS, STATUS_FAIL, STATUS_MISSING = "pass", "fail", "missing"


def evaluate_checks(metrics: pd.DataFrame, checks: list[dict]) -> pd.DataFrame:
    """One row per (check, run): the worst listed component, its value and the verdict."""
    rows = []
    for check in checks:
        passes, worst = OPERATORS[check["operator"]]
        regime = check.get("regime", REGIME_ALL)
        selected = metrics[(metrics.quantity == check["quantity"]) & (metrics.regime == regime)]
        runs = sorted(selected.run.unique()) if check["runs"] == ["*"] else check["runs"]
        for run in runs:
            values = selected[(selected.run == run) & selected.joint.isin(check["components"])]
            base = {"check": check["id"], "title": check["title"], "run": run, "operator": check["operator"], "threshold": float(check["threshold"]), "unit": check["unit"]}
            if len(values) < len(check["components"]) or values.value.isna().any():
                rows.append(base | {"component": ", ".join(check["components"]), "value": math.nan, "status": STATUS_MISSING})
                continue
            value = worst(values.value)
            component = values.joint[values.value == value].iloc[0]
            ok = all(passes(v, check["threshold"]) for v in values.value)
            rows.append(base | {"component": component, "value": float(value), "status": STATUS_PASS if ok else STATUS_FAIL})
    return pd.DataFrame(rows, columns=CHECK_COLUMNS)


#: published entries whose ratio says who is better (smaller is better); "effect"
#: entries (e.g. the error without counterweight) are compared without a verdict
KIND_ERROR, KIND_EFFECT = "error", "effect"

#: what a comparison target aims at: "smaller" (an error: ratio published / ours),
#: "equal" (a reproduction: the difference is shown), "none" (shown, not compared)
GOALS = ("smaller", "equal", "none")
#: a ratio beyond this compares a physical error with round-off, not two
#: simulators: it is reported as "at round-off" rather than as a number
MAX_MEANINGFUL_RATIO = 1e4

#: the note of a compared value at round-off (ahead of the entry's own note)
ROUND_OFF = "at round-off"

COMPARISON_COLUMNS = [
    "published", "kind", "source", "where", "run", "quantity", "regime", "component", "goal", "note",
    "published_value", "our_value", "unit", "ratio_published_over_ours", "reproduced_to",
]


def _units(entry: dict) -> list[str]:
    unit = entry["unit"]
    return list(unit) if isinstance(unit, list) else [unit] * len(entry["components"])


def compare_with_published(metrics: pd.DataFrame, published: dict) -> pd.DataFrame:
    """Each published number next to ours: for errors the ratio published / ours
    (> 1: we are better), for reproductions |ours - published|."""
    index = metrics.set_index(["run", "quantity", "joint", "regime"]).value
    index = index[~index.index.duplicated()]
    rows = []
    for entry in published.get("published", []):
        for target in entry.get("compare", []):
            quantity = target.get("quantity", entry["quantity"])
            regime = target.get("regime", REGIME_ALL)
            goal = target.get("goal", "smaller")
            for component, value, unit in zip(entry["components"], entry["values"], _units(entry)):
                ours = float(index.get((target["run"], quantity, component, regime), math.nan))
                ratio = value / ours if ours and math.isfinite(ours) else (math.inf if ours == 0 else math.nan)
                note = target.get("note", "")
                if goal != "smaller":
                    ratio = math.nan
                elif ratio > MAX_MEANINGFUL_RATIO:
                    ratio, note = math.nan, ROUND_OFF + (f"; {note}" if note else "")
                rows.append({
                    "published": entry["id"],
                    "kind": entry.get("kind", KIND_ERROR),
                    "source": entry["source"],
                    "where": entry["where"],
                    "run": target["run"],
                    "quantity": quantity,
                    "regime": regime,
                    "component": component,
                    "goal": goal,
                    "note": note,
                    "published_value": float(value),
                    "our_value": ours,
                    "unit": unit,
                    "ratio_published_over_ours": ratio,
                    "reproduced_to": abs(ours - value) if goal == "equal" else math.nan,
                })
    return pd.DataFrame(rows, columns=COMPARISON_COLUMNS)


def half_last_digit(published: float) -> float:
    """Half a unit of a published figure's last digit, as written (0.2394: 5e-5)."""
    return 0.5 * 10.0 ** decimal.Decimal(repr(float(published))).as_tuple().exponent


def on_not_determined(verdict: dict) -> bool:
    """A verdict that passes on a figure the diagnosis reports as not determined (a check that allows it says so: `not_determined`)."""
    return bool(verdict["passed"]) and bool(verdict.get("not_determined"))


#: "closer than" by less than this share of the bar is a tie, not a margin (the MTM's q2: 0.043413 against 0.043423)
TIE_SHARE = 1e-3


def closer_than(value: float, bar: float) -> dict:
    """A verdict's `passed` for "at least as close as `bar`", and `tie` where the two are within TIE_SHARE of it."""
    return {"passed": bool(value <= bar), "tie": bool(abs(value - bar) <= TIE_SHARE * abs(bar))}


def verdict_label(verdict: dict) -> str:
    """PASS, FAIL, PASS (not determined): a pass on a figure not determined is not a figure within its tolerance,
    or PASS (a tie): a pass within TIE_SHARE of its bar, which another setting may flip."""
    if not verdict["passed"]:
        return "FAIL"
    if on_not_determined(verdict):
        return "PASS (not determined)"
    return "PASS (a tie)" if verdict.get("tie") else "PASS"


def other_checks(verdicts: list[dict] | None) -> dict:
    """validate's verdicts beyond the check runs (diagnosis, contact), counted: passed, total, the failed ones,
    and how many of the passed rest on a figure not determined."""
    verdicts = verdicts or []
    return {"passed": sum(bool(v["passed"]) for v in verdicts), "total": len(verdicts),
            "not_determined": sum(on_not_determined(v) for v in verdicts),
            "failed": [f"{v['check']}: {v['value']}" for v in verdicts if not v["passed"]]}
