"""`make validate`: the campaign, the analysis and report, and the sim-to-real
diagnosis with its withheld-effect validations, in one command."""

from __future__ import annotations

import json
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pandas as pd

from dvrk_dart.io.atomic import write_json_atomic
from dvrk_dart.io.outputs import check_shared_folder, write_marker
from dvrk_dart.model.description import DEFAULT_MODEL_FILE
from dvrk_dart.paths import PIPELINES_DIR
from dvrk_dart.runs.campaign import load_campaign, needs_diagnosis, run_campaign


def _campaign(configs, runs_dir: Path, jobs: int, force: bool, label: str, executor: str = "local", ray_address: str | None = None) -> dict:
    print(f"{label}: {len(configs)} runs -> {runs_dir} ({jobs} workers, {executor} executor)")
    summary = run_campaign(configs, runs_dir, jobs=jobs, force=force, executor=executor, ray_address=ray_address)
    print(f"{label}: {len(summary['ran'])} ran, {len(summary['skipped_up_to_date'])} up to date, "
          f"{len(summary['failures'])} failed, {summary['wall_time_s']:.0f} s")
    return summary


#: the marker's kind of the folder `validate --out` fills in place
VALIDATION_KIND = "validation"

#: the identification's folder per processing (periodic: the default of `identify`)
IDENTIFICATION_FOLDERS = {"periodic": "identification", "upstream": "identification-upstream"}


def _identification_section(out_dir: Path) -> tuple[str, str]:
    """The project's own identification on "one", scored on the held-out "two", in both processings."""
    from dvrk_dart.identification.identify import IdentificationConfig
    from dvrk_dart.identification.outputs import identify_into_folder, report_section

    datas = []
    for processing, folder in IDENTIFICATION_FOLDERS.items():
        config = IdentificationConfig(runs=("one",), holdout=("two",), processing=processing)
        _, data = identify_into_folder(config, out_dir / folder)
        own = data["errors"]["holdout"]["two"]["first_period"]["relative_error"]
        published = data["reference"]["errors_first_period"].get("two", {}).get("relative_error")
        print(f"identification ({processing}): {data['n_base']} base parameters from one -> {out_dir / folder}; "
              f"held-out two, relative error of the first period J1..J7 {' '.join(f'{v:.4f}' for v in own)}"
              + (f" (published parameters {' '.join(f'{v:.4f}' for v in published)})" if published else ""))
        datas.append(data)
    return report_section(*datas)


def _independent_sections(out_dir: Path, runs_dir: Path) -> tuple:
    """The identification and periodic sections and every dataset's own identifications
    (they need the campaign, not the diagnosis)."""
    from dvrk_dart.datasets import identify_datasets

    identified = identify_datasets(out_dir / "datasets", _identified_2019(out_dir))
    return _identification_section(out_dir), _periodic_section(out_dir, runs_dir), identified


def _identified_2019(out_dir: Path) -> dict:
    """The identification section's folders (one -> two, both processings): the 2019 dataset's rows."""
    return {(("one",), ("two",), processing): out_dir / folder for processing, folder in IDENTIFICATION_FOLDERS.items()}


def _periodic_section(out_dir: Path, runs_dir: Path):
    """Both processings side by side, the session floor and the repeatable gap (analysis/periodic_section.py)."""
    from dvrk_dart.analysis.periodic_section import periodic_section
    from dvrk_dart.io.arm import load_arm

    section = periodic_section(load_arm(DEFAULT_MODEL_FILE), out_dir / "periodic", runs_dir)
    figures = json.loads((out_dir / "periodic" / "periodic.json").read_text())
    print("periodic: model vs measured on two, RMS J1..J3 (N·m, N·m, N), upstream "
          + " ".join(f"{v:.4f}" for v in figures["model_vs_measured_two"]["upstream"][:3]) + ", periodic "
          + " ".join(f"{v:.4f}" for v in figures["model_vs_measured_two"]["periodic"][:3]) + "; session floor "
          + " ".join(f"{v:.4f}" for v in figures["session_floor"]["rms_difference"][:3]))
    return section


def _datasets_section(out_dir: Path, identified: dict):
    """Every real PSM dataset's held-out figures side by side (dvrk_dart/datasets.py); `identified`: `identify_datasets`'."""
    from dvrk_dart.datasets import datasets_section
    from dvrk_dart.io.arm import load_arm

    return datasets_section(load_arm(DEFAULT_MODEL_FILE), out_dir / "datasets", out_dir / "diagnosis", identified)


#: the contact scenario: the held-out run replayed against a tissue-like surface (runs/contact.py)
CONTACT = {"run": "two", "depth_m": 0.01, "stiffness_n_per_m": 500.0, "damping_n_s_per_m": 5.0, "duration_s": 27.0}
#: the sim-to-sim bar of the force estimate (N RMS): the estimate is exact up to DART's integration
CONTACT_SIM_TO_SIM_BAR_N = 1e-3


def _contact_section(out_dir: Path) -> tuple[tuple[str, str], dict]:
    """DART's contact force against the estimate from the simulated efforts, and with each model's real residual added."""
    import numpy as np

    from dvrk_dart.io.html import num_cell, render, table, text_cell
    from dvrk_dart.diagnosis.effects.library import config_effort_by_formula
    from dvrk_dart.instrument_force import ForceConfig, model_efforts
    from dvrk_dart.io.reference_data import load_run, resolve_run
    from dvrk_dart.io.signal import process
    from dvrk_dart.io.arm import load_arm
    from dvrk_dart.runs.contact import contact_check, simulate_contact, surface_under
    from dvrk_dart.sim.config import SimConfig

    arm = load_arm(DEFAULT_MODEL_FILE)
    state = process(load_run(resolve_run(CONTACT["run"]), arm.model), "periodic")
    surface = surface_under(arm, state, CONTACT["depth_m"], stiffness_n_per_m=CONTACT["stiffness_n_per_m"],
                            damping_n_s_per_m=CONTACT["damping_n_s_per_m"])
    run = simulate_contact(arm, state, surface, CONTACT["duration_s"])
    model = config_effort_by_formula(arm, SimConfig(), run.q, run.dq, run.ddq)
    models = {"published parameters": "identified"}
    combined = out_dir / "diagnosis" / "holdout" / "one_configuration.json"
    if combined.is_file():
        models["diagnosis: one configuration"] = str(combined)
    results = {}
    for label, dynamics in models.items():  # each model's real residual on the run, at the contact run's times
        residual = state.tau - model_efforts(arm, ForceConfig(CONTACT["run"], dynamics, "periodic"), state)
        at_steps = np.column_stack([np.interp(run.t, state.t - state.t[0], residual[:, j]) for j in range(residual.shape[1])])
        results[label] = contact_check(arm, run, model, at_steps)
    check = {**CONTACT, "surface_height_m": surface.height_m, "models": results, "bar_n": CONTACT_SIM_TO_SIM_BAR_N}
    from dvrk_dart.io.atomic import write_json_atomic

    write_json_atomic(out_dir / "contact" / "contact.json", check)
    first = next(iter(results.values()))
    verdict = {"check": f"contact in DART: the force estimated from the simulated efforts within {CONTACT_SIM_TO_SIM_BAR_N:g} N RMS of "
                        "DART's applied contact force (sim-to-sim)", "passed": first["sim_to_sim_error_rms_n"] <= CONTACT_SIM_TO_SIM_BAR_N,
               "value": f"{first['sim_to_sim_error_rms_n']:.2e} N RMS (contact force {first['contact_force_rms_n']:.3f} N RMS, in contact "
                        f"{first['in_contact_fraction']:.0%} of the time)"}
    # one contact simulation (the inertial arm): its sim-to-sim figure is the first row's; the others add their model's real residual
    rows = [[text_cell(label), num_cell(r["sim_to_sim_error_rms_n"]) if r is first else text_cell("— (the same simulation)"),
             num_cell(r["with_real_residual_error_rms_n"]),
             *(num_cell(v) for v in r["with_real_residual_error_per_axis_n"]), num_cell(r["with_real_residual_error_in_contact_rms_n"])]
            for label, r in results.items()]
    worse_in_contact = [label for label, r in results.items()
                        if r["with_real_residual_error_in_contact_rms_n"] > first["with_real_residual_error_in_contact_rms_n"]]
    html = render("sections/contact.html", contact=CONTACT, force=first, worse_in_contact=worse_in_contact,
                  errors_table=table(["model", "sim-to-sim error (N RMS)", "with the real residual (N RMS)", "x (N)", "y (N)", "z (N)",
                                      "with the real residual, in contact (N RMS)"], rows))
    print(f"contact: {verdict['value']}; with the real residual (whole run, in contact): " + "; ".join(
        f"{label} {r['with_real_residual_error_rms_n']:.3f} N, {r['with_real_residual_error_in_contact_rms_n']:.3f} N" for label, r in results.items()))
    return ("Force at the instrument: a contact in DART", html), verdict


UNCERTAINTY_FILE = PIPELINES_DIR / "uncertainty.toml"
#: what `validate` records of itself in its --out folder
VALIDATE_SUMMARY = "validate.json"


def _uncertainty_section(out_dir: Path, jobs: int, executor: str, ray_address: str | None):
    """The Monte Carlo of pipelines/uncertainty.toml and its report section."""
    import tomllib

    from dvrk_dart.analysis.uncertainty_section import uncertainty_section
    from dvrk_dart.runs.uncertainty import UncertaintyConfig, run_uncertainty

    spec = tomllib.loads(UNCERTAINTY_FILE.read_text(encoding="utf-8"))
    config = UncertaintyConfig(spec["measured"], spec["samples"], spec["seed"], spec["relative_std"],
                               duration_s=spec["duration_s"], executor=executor, jobs=jobs)
    summary = run_uncertainty(config, out_dir / "uncertainty", ray_address)
    inside = ", ".join(f"{f:.2f}" for f in summary["measured_inside_band_fraction"][:3])
    print(f"uncertainty: {summary['samples_replayed']} parameter sets, measured inside the band on J1..J3: {inside} "
          f"({summary['wall_time_s']:.0f} s)")
    return uncertainty_section(out_dir / "uncertainty")


def validate(out_dir: Path, report_dir: Path, jobs: int = 2, force: bool = False, dynamics: str | None = None,
             executor: str = "local", ray_address: str | None = None) -> int:
    """The campaign (its entries without `dynamics` simulate the `dynamics` arm),
    the diagnosis validation, the runs that simulate what the diagnosis found,
    and the report."""
    check_shared_folder(out_dir, VALIDATION_KIND)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_marker(out_dir, VALIDATION_KIND, skip_marked=True)
    start, code = time.perf_counter(), None
    try:
        code = _validate(out_dir, report_dir, jobs, force, dynamics, executor, ray_address)
        return code
    finally:  # what this run wrote is the tool's, even when a stage failed: the next run may replace it
        wall = time.perf_counter() - start
        print(f"validate: {wall:.0f} s")
        # the whole campaign's time (make bench reads it; campaign.json's is the simulation runs' alone)
        write_json_atomic(out_dir / VALIDATE_SUMMARY, {"wall_time_s": wall, "jobs": jobs, "completed": code is not None})
        write_marker(out_dir, VALIDATION_KIND, skip_marked=True)


def _validate(out_dir: Path, report_dir: Path, jobs: int, force: bool, dynamics: str | None, executor: str,
              ray_address: str | None) -> int:
    runs_dir = out_dir / "runs"
    diagnosis_dir = out_dir / "diagnosis"
    configs = load_campaign(diagnosis_dir=diagnosis_dir, default_dynamics=dynamics)
    summary = _campaign([c for c in configs if not needs_diagnosis(c)], runs_dir, jobs, force, "campaign", executor, ray_address)

    from dvrk_dart.analysis.checks import verdict_label
    from dvrk_dart.analysis.report import build_report
    from dvrk_dart.diagnosis.checks.validation import validation_section

    # the Monte Carlo first: the held-out diagnosis calls an effect unmodelled only outside its band
    uncertainty = _uncertainty_section(out_dir, jobs, executor, ray_address)
    with ProcessPoolExecutor(max_workers=1) as beside:  # what needs no diagnosis, while the diagnoses run
        independent = beside.submit(_independent_sections, out_dir, runs_dir)
        section = validation_section(diagnosis_dir, parameter_band=out_dir / "uncertainty", jobs=jobs)
        identification, periodic, identified = independent.result()
    datasets = _datasets_section(out_dir, identified)
    contact, contact_verdict = _contact_section(out_dir)
    after = _campaign([c for c in configs if needs_diagnosis(c)], runs_dir, jobs, force, "diagnosed runs", executor, ray_address)
    summary["ran"] += after["ran"]
    summary["skipped_up_to_date"] += after["skipped_up_to_date"]
    summary["failures"].update(after["failures"])
    summary["runs"] += after["runs"]
    write_json_atomic(out_dir / "campaign.json", summary)
    others = [*json.loads((out_dir / "diagnosis" / "verdicts.json").read_text()), contact_verdict]
    index = build_report(runs_dir, report_dir, extra_sections=[section, datasets, contact, periodic, identification, uncertainty],
                         campaign_verdicts=others, every_check_run=True)
    checks = pd.read_csv(report_dir / "analysis" / "checks.csv")
    verdicts = checks.groupby(["check", "title"], sort=False)["status"].agg(lambda s: "pass" if (s == "pass").all() else "FAIL")
    print("verdicts:")
    for (check, title), status in verdicts.items():
        print(f"  [{status.upper():4}] {title}")
    for verdict in others:
        print(f"  [{verdict_label(verdict)}] {verdict['check']}: {verdict['value']}")
    print(f"report: {index.resolve()}")
    for name, error in summary["failures"].items():
        print(f"  failed run {name}: {error}")
    return 1 if summary["failures"] else 0
