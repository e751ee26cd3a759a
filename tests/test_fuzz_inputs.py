"""Property-based: malformed measured CSVs, parameter files and scenario files
always give exit code 2, one line on stderr, no traceback, and leave the
output folder as it was (Hypothesis generates the damage)."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dvrk_dart.cli import main
from dvrk_dart.io.reference_data import resolve, resolve_run
from dvrk_dart.runs.scenarios import SCENARIOS_DIR
from arms import PSM_ARM

#: few examples each: the three properties together stay well under a minute
FUZZ = settings(max_examples=50, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

GOOD_ROWS = np.loadtxt(resolve_run("two"), delimiter=",")[:450]
GOOD_PARAMS = json.loads(resolve(PSM_ARM.model.default_parameters).read_text())
GOOD_SCENARIO = (SCENARIOS_DIR / "spiral.toml").read_text()

junk_values = st.one_of(st.sampled_from(["nan", "inf", "-inf", "", "abc", "1e999", "0x10", "--1", "1,2"]),
                        st.text(alphabet="0123456789.eE+-x ;", min_size=1, max_size=6))
json_junk = st.one_of(st.none(), st.booleans(), st.text(max_size=5), st.just(float("nan")), st.just(1e30), st.just(-1.0),
                      st.lists(st.floats(allow_nan=True), max_size=4), st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))


def expect_clean_refusal(capsys, argv: list[str], out: Path) -> None:
    before = sorted(p.name for p in out.parent.iterdir())
    code = main(argv)
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2, (argv, err)
    assert len(err) == 1 and err[0].startswith("dvrk-dart: ") and "Traceback" not in err[0], err
    assert sorted(p.name for p in out.parent.iterdir()) == before and not out.exists()


@st.composite
def malformed_csvs(draw) -> str:
    rows = [[repr(v) for v in row] for row in GOOD_ROWS]
    damage = draw(st.sampled_from(["value", "columns", "rows", "binary", "range"]))
    if damage == "value":
        i, j = draw(st.integers(0, len(rows) - 1)), draw(st.integers(0, 20))
        rows[i][j] = draw(junk_values)
    elif damage == "columns":
        i = draw(st.integers(0, len(rows) - 1))
        rows[i] = rows[i][: draw(st.integers(0, 20))] if draw(st.booleans()) else rows[i] + ["0.0"]
    elif damage == "rows":
        rows = rows[: draw(st.integers(0, 401))]
    elif damage == "range":
        i, j = draw(st.integers(0, len(rows) - 1)), draw(st.integers(0, 6))
        rows[i][j] = repr(draw(st.sampled_from([5.0, -4.0, 1e300, -1e300])))
    else:
        return "\udcff"  # not UTF-8 once written with surrogateescape
    return "\n".join(",".join(r) for r in rows) + "\n"


@FUZZ
@given(text=malformed_csvs())
def test_malformed_measured_runs_are_refused_cleanly(tmp_path_factory, capsys, text):
    folder = tmp_path_factory.mktemp("csv")
    path = folder / "run.csv"
    path.write_bytes(text.encode("utf-8", "surrogateescape"))
    expect_clean_refusal(capsys, ["replay", "--measured", str(path), "--out", str(folder / "out")], folder / "out")


@st.composite
def malformed_params(draw) -> dict:
    raw = json.loads(json.dumps(GOOD_PARAMS))
    link = draw(st.sampled_from(sorted(raw, key=int)))
    key = draw(st.sampled_from(["m", "r", "I", "Fc", "Fv", "Fo", "Im", "K"]))
    if draw(st.booleans()):
        raw[link].pop(key)
    else:
        raw[link][key] = draw(json_junk)
    return raw


@FUZZ
@given(raw=malformed_params())
def test_malformed_parameter_files_are_refused_cleanly(tmp_path_factory, capsys, raw):
    folder = tmp_path_factory.mktemp("params")
    path = folder / "params.json"
    path.write_text(json.dumps(raw))
    argv = ["replay", "--measured", "two", "--duration", "0.05", "--params", str(path), "--out", str(folder / "out")]
    code = main(argv)
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    if code == 0:  # a damage that is still a valid file (e.g. a friction set to -1): it ran
        assert (folder / "out" / "metrics.json").is_file()
        return
    assert code == 2 and len(err) == 1 and err[0].startswith("dvrk-dart: ") and str(path) in err[0], err
    assert not (folder / "out").exists()


#: values each scenario key must refuse (the schema: types, units, ranges)
INVALID_SCENARIO_VALUES = {
    "name": st.sampled_from([5, "", "a/b", ["x"]]),
    "kind": st.one_of(st.integers(), st.sampled_from(["circle", "", "Cartesian"])),
    "duration_s": st.sampled_from([-1.0, 0.0, math.inf, "10", True, [1.0]]),
    "modes": st.sampled_from([5, [], ["kinematic", 5], "kinematic", ["fast"]]),
    "counterweights": st.sampled_from([5, [], ["maybe"], "on"]),
    "start_pose": st.sampled_from(["home", [1, 2], [0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 0.0], [0, 0, 0.1, 0, 0, 0, "x"]]),
    "path": st.sampled_from([5, "spiral"]),
    "extra_key": st.one_of(st.integers(), st.text(max_size=4)),
}
REQUIRED_SCENARIO_KEYS = ("kind", "duration_s", "modes", "start_pose", "path")


@st.composite
def malformed_scenarios(draw) -> str:
    raw = tomllib.loads(GOOD_SCENARIO)
    if draw(st.booleans()):
        raw.pop(draw(st.sampled_from(REQUIRED_SCENARIO_KEYS)))
    else:
        key = draw(st.sampled_from(sorted(INVALID_SCENARIO_VALUES)))
        raw[key] = draw(INVALID_SCENARIO_VALUES[key])
    return toml_text(raw)


def toml_text(raw: dict) -> str:
    """A minimal TOML writer for the generated scenarios (flat values and one table)."""
    def value(v):
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, float):
            return "inf" if v == math.inf else repr(v)
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return str(v)

    lines = [f"{k} = {value(v)}" for k, v in raw.items() if not isinstance(v, dict)]
    for k, v in raw.items():
        if isinstance(v, dict):
            lines += [f"[{k}]", *[f"{kk} = {value(vv)}" for kk, vv in v.items()]]
    return "\n".join(lines) + "\n"


@FUZZ
@given(text=malformed_scenarios())
def test_malformed_scenario_files_are_refused_cleanly(tmp_path_factory, capsys, text):
    folder = tmp_path_factory.mktemp("scenario")
    path = folder / "scenario.toml"
    path.write_text(text)
    expect_clean_refusal(capsys, ["run", str(path), "--duration", "0.05", "--out", str(folder / "out")], folder / "out")
