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

from dvrk_dart.io.html import num_cell, render, table, text_cell
from dvrk_dart.io.atomic import write_json_atomic
from dvrk_dart.io.reference_data import load_run, resolve_run
from dvrk_dart.io.signal import PROCESSINGS, process
from dvrk_dart.metrics import per_measured_joint, rms
from dvrk_dart.io.arm import Arm
from dvrk_dart.model.joints import JOINT_NAMES
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
    state = process(load_run(resolve_run(run), arm.model), processing)
    residual = state.tau - state.in_band(arm.identified.predict(state.q, state.dq, state.ddq, "all"))
    return per_measured_joint(rms(residual), state.measured)


def own_identification(dataset: Dataset, processing: str, out_dir: Path, identified: dict) -> Path:
    """The folder of `identify --runs TRAIN --holdout HOLDOUT --processing P`:
    one `identified` already holds ({(train, holdout, processing): folder}), else made in out_dir."""
    from dvrk_dart.identification.identify import IdentificationConfig
    from dvrk_dart.identification.outputs import identify_into_folder

    key = (tuple(dataset.train), (dataset.holdout,), processing)
    if key in identified:
        return Path(identified[key])
    folder = out_dir / f"identification-{processing}"
    identify_into_folder(IdentificationConfig(runs=dataset.train, holdout=(dataset.holdout,), processing=processing), folder)
    return folder


def identify_datasets(out_dir: Path, identified: dict) -> dict:
    """Every dataset's own identifications (each processing) not in `identified`, made in
    out_dir/<dataset>/: they need no diagnosis, so `make validate` makes them beside the diagnoses."""
    made = dict(identified)
    for dataset in load_datasets():
        for p in PROCESSINGS:
            made[(tuple(dataset.train), (dataset.holdout,), p)] = own_identification(dataset, p, out_dir / dataset.name, identified)
    return made


def own_identification_rms(dataset: Dataset, folder: Path) -> list[float | None]:
    """The held-out run's whole-run RMS of an identification folder."""
    from dvrk_dart.identification.outputs import SUMMARY_FILE

    return json.loads((folder / SUMMARY_FILE).read_text())["errors"]["holdout"][dataset.holdout]["whole_run"]["rms"]


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


def dataset_figures(arm: Arm, dataset: Dataset, out_dir: Path, diagnosis_dir: Path, identified: dict) -> dict:
    folder = out_dir / dataset.name
    own = {p: own_identification(dataset, p, folder, identified) for p in PROCESSINGS}
    figures = {
        "title": dataset.title, "train": list(dataset.train), "holdout": dataset.holdout,
        "published": {p: published_rms(arm, dataset.holdout, p) for p in PROCESSINGS},
        "own_identification": {p: own_identification_rms(dataset, own[p]) for p in PROCESSINGS},
        "diagnosis": diagnosis_rms(diagnosis_dir, dataset.diagnosis_case),
    }
    figures["phantom_force"] = phantom_forces(arm, dataset, folder, diagnosis_dir, own["periodic"])
    write_json_atomic(folder / FIGURES_FILE, figures)
    return figures


def phantom_forces(arm: Arm, dataset: Dataset, folder: Path, diagnosis_dir: Path, own_periodic: Path) -> dict:
    """`dvrk-dart force` on the held-out run (periodic) under each model: the force it
    implies in free motion, where the true force is zero; the figure of one period."""
    from dvrk_dart.instrument_force import ForceConfig, instrument_force, one_period_forces
    from dvrk_dart.io.arm import load_arm

    models = {"published parameters": (arm, "identified"),
              "own identification": (load_arm(arm.model.source, own_periodic / "params.json"), "identified")}
    combined = diagnosis_dir / dataset.diagnosis_case / "one_configuration.json"
    if combined.is_file():
        models["diagnosis: one configuration"] = (arm, str(combined))
    forces = {label: instrument_force(model, ForceConfig(dataset.holdout, dynamics, "periodic"), None)
              for label, (model, dynamics) in models.items()}
    period = {label: one_period_forces(model, ForceConfig(dataset.holdout, dynamics, "periodic"))
              for label, (model, dynamics) in models.items() if label != "own identification"}
    plot_phantom_force(period, folder / PHANTOM_FIGURE, dataset.holdout)
    keep = ("rms_n", "p95_n", "rms_per_axis_n", "determined_fraction", "determined_part_rms_n", "rms_all_samples_n", "min_lever_m", "point")
    return {label: {k: summary[k] for k in keep} for label, summary in forces.items()}


PHANTOM_FIGURE = "phantom_force_one_period.png"


def plot_phantom_force(period: dict, path: Path, run: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3.2))
    for label, (t, force) in period.items():
        ax.plot(t, np.linalg.norm(force, axis=1), label=label)
    ax.set_xlabel("time in the period (s)")
    ax.set_ylabel("|F| at the instrument (N)")
    ax.set_title(f"phantom force on held-out {run}, free motion (gaps: lever under the limit)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def datasets_section(arm: Arm, out_dir: Path, diagnosis_dir: Path, identified: dict | None = None) -> tuple[str, str, list[Path]]:
    """(title, html, figures) of the report: one table per dataset, the same rows;
    `identified`: identification folders already made ({(train, holdout, processing): folder})."""
    shown, files = [], []
    for dataset in load_datasets():
        figures = dataset_figures(arm, dataset, out_dir, diagnosis_dir, identified or {})
        print(f"dataset {dataset.name}: held-out {dataset.holdout}, RMS J1..J3 (N·m, N·m, N; the last row a ratio): " + "; ".join(
            f"{label} " + " ".join("-" if v is None else f"{v:.4f}" for v in values[:3]) for label, values in _rows(figures)))
        print(f"dataset {dataset.name}: phantom force at the instrument on {dataset.holdout}, |F| RMS where determined "
              f"({next(iter(figures['phantom_force'].values()))['determined_fraction']:.0%} of the samples) and in the determined "
              "directions over every sample: " + "; ".join(f"{label} {f['rms_n']:.3f} N, {f['determined_part_rms_n']:.3f} N"
                                                          for label, f in figures["phantom_force"].items() if f["rms_n"] is not None))
        staged = out_dir / f"{dataset.name}_{PHANTOM_FIGURE}"  # the report copies extras by file name: keep them apart
        staged.write_bytes((out_dir / dataset.name / PHANTOM_FIGURE).read_bytes())
        files.append(staged)
        first = next(iter(figures["phantom_force"].values()))
        shown.append({"title": dataset.title, "name": dataset.name, "train": dataset.train, "holdout": dataset.holdout,
                      "rms_table": _table(dataset, figures, arm.model), "force_table": _force_table(dataset, figures["phantom_force"]),
                      "point": first["point"], "min_lever_m": first["min_lever_m"], "figure": staged.name})
    body = render("sections/datasets.html", datasets=shown, figures_folder=out_dir.name, figures_file=FIGURES_FILE)
    return "Every real dataset: held-out figures side by side", body, files


def _force_table(dataset: Dataset, forces: dict) -> str:
    """The phantom force per model: what the effort gap costs at the instrument."""
    rows = []
    for label, f in forces.items():
        cells = [f["rms_n"], f["p95_n"], *(f["rms_per_axis_n"] or [None] * 3)]
        rows.append([text_cell(label), *(num_cell(v, dataset=dataset.name, row=f"phantom force: {label}") for v in cells),
                     text_cell(f"{f['determined_fraction']:.0%}"),
                     num_cell(f.get("determined_part_rms_n"), dataset=dataset.name, row=f"phantom force, every sample: {label}")])
    # no |F| over every sample: near the remote centre J^-T divides by a lever going to zero, so that figure is the
    # trajectory's geometry, not the model (2018-test2: 5e3 N with 32 % of samples left out); the determined directions
    # are kept on every sample instead (the samples left out are where a model may fail: 2018's one configuration on J3)
    return table(["model", "|F| RMS (N)", "95th percentile (N)", "x RMS (N)", "y RMS (N)", "z RMS (N)", "samples determined",
                  "determined directions, every sample (N RMS)"], rows)


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


def _table(dataset: Dataset, figures: dict, model) -> str:
    joints = [j for j, v in enumerate(figures["published"]["upstream"]) if v is not None][:3]
    header = ["held-out " + dataset.holdout, *(f"{JOINT_NAMES[j]} ({model.effort_unit(JOINT_NAMES[j])})" for j in joints)]
    rows = []
    for label, values in _rows(figures):
        rows.append([text_cell(label), *(num_cell(values[j], dataset=dataset.name, row=label, joint=JOINT_NAMES[j]) for j in joints)])
    return table(header, rows)

