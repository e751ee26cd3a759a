"""Every real PSM dataset side by side (`make validate`, pipelines/datasets.toml).

A result counts when it holds on data it was not tuned on: the project was
built on the `wpi/` runs (2019); `wpi-2018/` is another session of the same
lab, another excitation design and 3-joint logs. For each dataset, on its
held-out run, in the same table: the published parameters and the project's
own identification (trained on the dataset's training runs) in both
processings, and the diagnosis's one configuration against the identified
model in the diagnosis's band (the withheld-data validation's case of that
dataset, `pipelines/withheld.toml`)."""

from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dvrk_dart.analysis.html import fmt, num_cell, table, text_cell
from dvrk_dart.io.atomic import write_json_atomic
from dvrk_dart.io.reference_data import load_run, resolve_run
from dvrk_dart.io.signal import PROCESSINGS, process
from dvrk_dart.metrics import per_measured_joint, rms
from dvrk_dart.model.arm import Arm
from dvrk_dart.model.joints import JOINT_NAMES, effort_unit
from dvrk_dart.paths import PIPELINES_DIR

DATASETS_FILE = PIPELINES_DIR / "datasets.toml"
FIGURES_FILE = "datasets.json"


@dataclass(frozen=True)
class Dataset:
    name: str
    title: str
    train: tuple[str, ...]
    holdout: str
    #: the withheld-data validation's case (out/diagnosis/<case>/diagnosis.json) that diagnoses it
    diagnosis_case: str


def load_datasets(path: Path = DATASETS_FILE) -> list[Dataset]:
    raw = tomllib.loads(path.read_text(encoding="utf-8"))
    return [Dataset(d["name"], d["title"], tuple(d["train"]), d["holdout"], d["diagnosis_case"]) for d in raw["datasets"]]


def published_rms(arm: Arm, run: str, processing: str) -> list[float | None]:
    """The published parameters on a whole run (model-errors' figures; None where not recorded)."""
    state = process(load_run(resolve_run(run)), processing)
    residual = state.tau - state.in_band(arm.identified.predict(state.q, state.dq, state.ddq, "all"))
    return per_measured_joint(rms(residual), state.measured)


def own_identification_rms(dataset: Dataset, processing: str, out_dir: Path) -> list[float | None]:
    """`identify --runs TRAIN --holdout HOLDOUT --processing P`: the held-out run's whole-run RMS."""
    from dvrk_dart.identification.identify import IdentificationConfig
    from dvrk_dart.identification.outputs import identify_into_folder

    config = IdentificationConfig(runs=dataset.train, holdout=(dataset.holdout,), processing=processing)
    _, data = identify_into_folder(config, out_dir / f"identification-{processing}")
    return data["errors"]["holdout"][dataset.holdout]["whole_run"]["rms"]


def diagnosis_rms(diagnosis_dir: Path, case: str) -> dict | None:
    """The identified model and the one configuration on the case's held-out runs (its diagnosis.json)."""
    path = diagnosis_dir / case / "diagnosis.json"
    if not path.is_file():
        return None
    result = json.loads(path.read_text())
    combined = result.get("one_configuration") or {}
    return {"processing": result["processing"]["processing"], "harmonics": result["processing"].get("harmonics"),
            "identified_model": result.get("identified_model_gap_holdout"), "one_configuration": combined.get("gap_holdout"),
            "selected_effects_alone": result["gap_after"]["holdout"]}


def dataset_figures(arm: Arm, dataset: Dataset, out_dir: Path, diagnosis_dir: Path) -> dict:
    folder = out_dir / dataset.name
    figures = {
        "title": dataset.title, "train": list(dataset.train), "holdout": dataset.holdout,
        "published": {p: published_rms(arm, dataset.holdout, p) for p in PROCESSINGS},
        "own_identification": {p: own_identification_rms(dataset, p, folder) for p in PROCESSINGS},
        "diagnosis": diagnosis_rms(diagnosis_dir, dataset.diagnosis_case),
    }
    write_json_atomic(folder / FIGURES_FILE, figures)
    return figures


def datasets_section(arm: Arm, out_dir: Path, diagnosis_dir: Path) -> tuple[str, str]:
    """(title, html) of the report: one table per dataset, the same rows."""
    parts = ["<p>Every figure is the RMS of measured minus predicted efforts on the held-out run, whole run "
             "(N·m, N for q3). The published parameters were identified on the 2019 runs; the project's own are trained on the "
             "dataset's training runs only; the diagnosis is fitted on them too (its band: the smallest cutoff of its runs).</p>"]
    for dataset in load_datasets():
        figures = dataset_figures(arm, dataset, out_dir, diagnosis_dir)
        print(f"dataset {dataset.name}: held-out {dataset.holdout}, " + "; ".join(
            f"{label} " + " ".join("-" if v is None else f"{v:.4f}" for v in values[:3]) for label, values in _rows(figures)))
        parts.append(_table(dataset, figures))
    return "Every real dataset: held-out figures side by side", "".join(parts)


def _rows(figures: dict) -> list[tuple[str, list]]:
    rows = [(f"published parameters, {p}", figures["published"][p]) for p in PROCESSINGS]
    rows += [(f"own identification, {p}", figures["own_identification"][p]) for p in PROCESSINGS]
    diagnosis = figures["diagnosis"]
    if diagnosis and diagnosis["identified_model"] and diagnosis["one_configuration"]:
        band = f"{diagnosis['processing']}, {diagnosis['harmonics']} harmonics" if diagnosis["harmonics"] else diagnosis["processing"]
        rows += [(f"identified model, the diagnosis's band ({band})", diagnosis["identified_model"]),
                 ("diagnosis: the selected effects", diagnosis["selected_effects_alone"]),
                 ("diagnosis: one configuration", diagnosis["one_configuration"]),
                 ("one configuration / identified model", _ratio(diagnosis["one_configuration"], diagnosis["identified_model"]))]
    return rows


def _ratio(a: list, b: list) -> list:
    return [None if x is None or not y else x / y for x, y in zip(a, b)]


def _table(dataset: Dataset, figures: dict) -> str:
    joints = [j for j, v in enumerate(figures["published"]["upstream"]) if v is not None][:3]
    header = ["held-out " + dataset.holdout, *(f"{JOINT_NAMES[j]} ({effort_unit(JOINT_NAMES[j])})" for j in joints)]
    rows = []
    for label, values in _rows(figures):
        cells = "".join(num_cell(values[j], dataset=dataset.name, row=label, joint=JOINT_NAMES[j]) for j in joints)
        rows.append(f"<tr>{text_cell(label)}{cells}</tr>")
    intro = (f"<h3>{dataset.title}</h3><p>Trained on {', '.join(dataset.train)}, held out: {dataset.holdout}. "
             f"Figures in <code>{dataset.name}/{FIGURES_FILE}</code>.</p>")
    return intro + table(header, rows)


__all__ = ["load_datasets", "dataset_figures", "datasets_section", "fmt", "np"]
