"""Is a gap inside what the parameters' uncertainty allows?

`dvrk-dart uncertainty` replays a run with parameter sets drawn from the
identified parameters' uncertainty and writes the 5-95 % band of the simulated
efforts. Where the measured efforts of that run stay inside the band, the
identified model with its uncertain parameters already explains them: an
effect the diagnosis selects on such a joint is reported as "within the
parameters' uncertainty", not as an unmodelled effect. Only joints whose
measured efforts leave the band more often than the band's own coverage allows
make an effect unmodelled.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.reference_data import run_label
from dvrk_dart.model.joints import JOINT_NAMES

#: a 5-95 % band holds 90 % of the efforts the uncertain parameters produce: a
#: run inside it less often than that is not explained by them alone
BAND_COVERAGE = 0.90
#: a replay of a whole run spans its duration less what the processing trims
#: at the ends (2 s at 200 Hz) and a margin: a shorter band covers part of the run
TRIMMED_ENDS_S = 2.5


def load_band(folder: str | Path) -> dict:
    """The summary (uncertainty.json) of a `dvrk-dart uncertainty` output folder."""
    path = Path(folder) / "uncertainty.json"
    if not path.is_file():
        raise DvrkDartError(f"--parameter-band: {folder} is not an output folder of `dvrk-dart uncertainty` (no uncertainty.json)")
    try:
        band = json.loads(path.read_text(encoding="utf-8"))
        lengths = {key: len([None if v is None else float(v) for v in band[key]]) for key in ("measured_inside_band_fraction", "rms_measured_outside_band")}
        measured = band["config"]["measured"]
        digest, replayed = str(band["measured_file"]["sha256"]), float(band["measured_file"]["replayed_s"])
    except (ValueError, KeyError, TypeError, UnicodeDecodeError) as exc:
        raise DvrkDartError(f"--parameter-band: {path}: not an uncertainty summary of this version (missing or bad {exc}): "
                            "run dvrk-dart uncertainty again") from None
    for key, n in lengths.items():
        if n != len(JOINT_NAMES):
            raise DvrkDartError(f"--parameter-band: {path}: {n} joints in {key}, expected {len(JOINT_NAMES)}")
        if not all(v is None or math.isfinite(float(v)) for v in band[key]):  # NaN compares false: "outside on no joint"
            raise DvrkDartError(f"--parameter-band: {path}: {key} holds a value that is not finite (a joint not recorded is null)")
    return {**band, "folder": str(folder), "run": run_label(measured), "sha256": digest, "replayed_s": replayed}


def band_run(band: dict, runs_sha256: dict[str, str]) -> str:
    """The diagnosed run (name -> content sha256) whose band `band` is; refused
    in one line when it is none of them (call it before the diagnosis runs)."""
    diagnosed = {digest: name for name, digest in runs_sha256.items()}
    if band["sha256"] not in diagnosed:
        raise DvrkDartError(f"--parameter-band: the band of {band['folder']} is of a recording ({band['run']}, sha256 "
                            f"{band['sha256'][:12]}...) that is none of the diagnosed runs ({', '.join(runs_sha256)})")
    return diagnosed[band["sha256"]]


def apply_band(result: dict, band: dict) -> dict:
    """A diagnosis result with each effect marked as beyond the parameters'
    uncertainty or within it, and the per-joint band summary (a new dict)."""
    run = band_run(band, {name: entry["sha256"] for name, entry in result.get("inputs", {}).items()})
    inside = band["measured_inside_band_fraction"]
    outside = {j for j, fraction in zip(JOINT_NAMES, inside) if fraction is not None and fraction < BAND_COVERAGE}
    effects = [{**effect, "beyond_parameter_uncertainty": bool(outside.intersection(effect["joints"]))} for effect in result["effects"]]
    selected = [e for e in effects if e["selected"]]
    return {**result, "effects": effects, "parameter_band": {
        "folder": band["folder"],
        "run": run,
        "sha256": band["sha256"],
        "replayed_s": band["replayed_s"],
        "run_duration_s": band.get("run_duration_s"),
        "parameters": band.get("parameters"),
        "rule": f"an effect is unmodelled only on a joint whose measured efforts are inside the band less than "
                f"{BAND_COVERAGE:.0%} of the time (the band's own coverage)",
        "measured_inside_band_fraction": dict(zip(JOINT_NAMES, inside)),
        "rms_measured_outside_band": dict(zip(JOINT_NAMES, band["rms_measured_outside_band"])),
        "joints_outside_band": [j for j in JOINT_NAMES if j in outside],
        "unmodelled_effects": [e["name"] for e in selected if e["beyond_parameter_uncertainty"]],
        "within_parameter_uncertainty": [e["name"] for e in selected if not e["beyond_parameter_uncertainty"]],
    }}


def band_sentence(result: dict) -> str | None:
    """One sentence for the CLI and the HTML, or None without a band."""
    band = result.get("parameter_band")
    if band is None:
        return None
    unmodelled = ", ".join(band["unmodelled_effects"]) or "none"
    within = ", ".join(band["within_parameter_uncertainty"]) or "none"
    outside = ", ".join(band["joints_outside_band"]) or "no joint"
    duration = band.get("run_duration_s")
    partial = duration and band["replayed_s"] < duration - TRIMMED_ENDS_S
    span = f" (over its first {band['replayed_s']:.1f} s of {duration:.1f} s)" if partial else ""
    drawn = f" ({band['parameters']})" if band.get("parameters") else ""
    return (f"parameter band of '{band['run']}'{span}: measured efforts outside it on {outside}; "
            f"unmodelled effects: {unmodelled}; within the band the drawn parameters span{drawn}: {within}")
