"""What `dvrk-dart identify` writes into its folder:

- `params.json`: the upstream layout (keys "1".."16"; m, r and I about the
  centre of mass with the base-frame axes at q = 0; Fc, Fv, Fo, Im, K), read
  by every command that takes `--params`;
- `params_covariance.json`: the uncertainty of the standard parameters, for
  `dvrk-dart uncertainty --params-cov FILE`:
      {"format": "dvrk-dart-params-covariance/1",
       "names":   ["link1.m", "link1.mcx", ..., "link10.K"],   # standard parameters
       "units":   ["kg", "kg m", ...],
       "nominal": [...],                                       # the identified values (SI)
       "covariance": [[...], ...],                             # n x n, SI units
       "frame": ..., "params_file": "params.json", "friction_law": "sign(v)", "basis": ...}
  Names: `link<key>.<m|mcx|mcy|mcz|Ixx|Ixy|Iyy|Ixz|Iyz|Izz|Fc|Fv|Fo|Im|K>`,
  where m c and I are Pinocchio's dynamic parameters (first moment, inertia
  about the *link frame origin*, link-frame axes; params.json holds the same
  bodies as m, r, I about the centre of mass in base axes). The covariance is
  that of the weighted fit on the base parameters beta = K theta, mapped to the
  standard ones with the minimum-norm inverse of K: C = K+ C_beta K+^T. It
  varies only the combinations the data determine (the rest, set by the
  prior and the constraints, is held at its nominal value), and a sample
  nominal + L z need not be physically consistent: project or reject;
- `identification.json`: errors per run and joint, base parameters with
  standard errors, condition number, identifiable parameters and those set by
  the constraints, pseudo-inertia eigenvalues, masses and bounds, timings;
- `identification.html`: measured vs predicted efforts (training and held-out
  runs, first period) and the parameter tables.
"""

from __future__ import annotations

import base64
import io
import math
from pathlib import Path

import numpy as np

from dvrk_dart.io.html import fmt, num_cell, render, table, text_cell
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.identification.fit import MAX_CONDITION_NUMBER, PSD_MARGIN_KG_M2
from dvrk_dart.identification.identify import (
    IdentificationConfig,
    IdentificationResult,
    RunData,
    identify,
)
from dvrk_dart.identification.regressor import body_of, params_json, standard_vector
from dvrk_dart.io.atomic import json_text, write_json_atomic, write_text_atomic
from dvrk_dart.io.provenance import file_record, software_versions
from dvrk_dart.io.reference_data import input_record, resolve
from dvrk_dart.model.joints import INSERTION, JOINT_NAMES
from dvrk_dart.model.parameters import load_parameters
from dvrk_dart.model.pseudo_inertia import pseudo_inertia

PARAMS_FILE = "params.json"
COVARIANCE_FILE = "params_covariance.json"
SUMMARY_FILE = "identification.json"
HTML_FILE = "identification.html"
COVARIANCE_FORMAT = "dvrk-dart-params-covariance/1"
#: what an identification writes in its folder
FOLDER_ENTRIES = (PARAMS_FILE, COVARIANCE_FILE, SUMMARY_FILE, HTML_FILE)


def parameter_units(result: IdentificationResult) -> list[str]:
    units = []
    links = result.model.links
    for name in result.regressor.layout.names:
        key, what = name.split(".", 1)
        prismatic = bool(links[int(key[4:])].variable.coeffs[INSERTION]) if what in ("Fc", "Fv", "Fo") else False
        force = "N" if prismatic else "N·m"
        units.append({
            "m": "kg", "mcx": "kg m", "mcy": "kg m", "mcz": "kg m", "Fc": force, "Fo": force,
            "Fv": f"{force} s/{'m' if prismatic else 'rad'}", "Im": "kg m^2", "K": "N·m/rad",
        }.get(what, "kg m^2"))
    return units


def standard_covariance(result: IdentificationResult) -> np.ndarray:
    K_plus = np.linalg.pinv(result.base.K)
    C = K_plus @ result.wls.covariance @ K_plus.T
    return 0.5 * (C + C.T)


def pseudo_inertia_eigenvalues(result: IdentificationResult) -> dict[str, list[float]]:
    layout = result.regressor.layout
    return {str(k): np.linalg.eigvalsh(pseudo_inertia(*body_of(result.theta, layout, k))).tolist() for k in layout.inertial_links}


def reference_theta(result: IdentificationResult) -> tuple[np.ndarray, str, float] | None:
    """The model's default parameters (the published identification): theta, file,
    smallest pseudo-inertia eigenvalue; None when the file cannot be found."""
    try:
        path = resolve(result.model.default_parameters)
        params = load_parameters(path, result.model)
    except DvrkDartError:
        return None
    layout = result.regressor.layout
    worst = min(float(np.linalg.eigvalsh(pseudo_inertia(p.mass, p.com, p.inertia_com))[0]) for k, p in params.links.items() if k in layout.inertial_links)
    return standard_vector(params, layout), str(path), worst


def _input_files(result: IdentificationResult, reference: tuple | None) -> dict[str, dict]:
    """The files besides the runs the identification read (the arm's model card, the bounds, the prior's and
    the published parameters): path and sha256."""
    files = {"model_file": result.model.source, "bounds_file": result.bounds.source,
             "prior_file": result.prior_source if Path(result.prior_source).is_file() else None,
             "reference_params_file": reference[1] if reference else None}
    return {key: file_record(Path(path)) for key, path in files.items() if path is not None}


def _run_entry(run: RunData, result: IdentificationResult) -> dict:
    return {"name": run.name, **input_record(run.path, result.model, result.config.topics), "samples_after_processing": len(run.processed)}


def _processing(result: IdentificationResult) -> dict:
    """How the runs were processed, with each run's period, harmonics and noise (periodic)."""
    runs = result.train + result.holdout
    first = runs[0].processed
    return {
        "processing": first.processing,
        "chosen_because": result.processing_note or (f"--processing {result.config.processing}" if result.config.processing
                                                      else "every run is a periodic excitation"),
        "first_period": f"the first {first.first_period_samples()} processed samples" if first.periodic is None
                        else "the first fitted period of the run's projected signals",
        "runs": {run.name: run.processed.summary() for run in runs},
    }


#: what summary()'s figures mean (identification.json's "definitions")
DEFINITIONS = {
    "relative_error": "||tau_predicted - tau_measured|| / ||tau_measured|| per joint (metrics.relative_error)",
    "rms": "root mean square of tau_predicted - tau_measured per joint, N·m (N for q3)",
    "condition_number": "of the training runs' base regressor with unit-norm columns",
    "noise_sigma": "upstream: per-joint residual standard deviation of the first, unweighted fit (the weights); "
                   "periodic: per-joint RMS of the measured noise of the efforts' harmonic coefficients (the weights are per coefficient)",
    "residual_autocorrelation_samples": "upstream: integrated autocorrelation time of that residual (the covariance counts this many "
                                        "samples as one); periodic: 1 (the coefficients' noises are independent)",
    "standard_error": "upstream: from the residual (model error included); periodic: from the measured noise alone "
                      "(what repeating the run would scatter the estimate by; the model's own error is not in it)",
}


#: how each friction link's pre-sliding distance is chosen
PRESLIDING_DEFINITION = ("per friction link: the distance over which its Coulomb friction reverses (Dahl; 0 = sign), "
                         "chosen on the training runs by their weighted fit's residual (sum over fitted joints of "
                         "(rms / rms with sign)^2), from the bounds file's [presliding] candidates")


def _errors(result: IdentificationResult):
    """The fit's errors on its runs; the prior's on the held-out runs' first period, the reference parameters' on
    their whole run and first period (as the fit's)."""
    errors = {
        "train": {run.name: {"whole_run": result.errors(run)} for run in result.train},
        "holdout": {
            run.name: {"whole_run": result.errors(run), "first_period": result.errors(run, first_period=True)} for run in result.holdout
        },
    }
    prior_errors = {} if not np.any(result.prior_theta) else {
        run.name: result.errors(run, first_period=True, theta=result.prior_theta, sign_law=True) for run in result.holdout
    }
    reference = reference_theta(result)
    reference_errors = {span: {run.name: result.errors(run, first_period=span == "first_period", theta=reference[0], sign_law=True)
                               for run in result.holdout} if reference else {} for span in ("whole_run", "first_period")}
    return errors, prior_errors, reference, reference_errors


def summary(result: IdentificationResult) -> dict:
    base, wls, cfg = result.base, result.wls, result.config
    errors, prior_errors, reference, reference_errors = _errors(result)
    return {
        "joints": list(JOINT_NAMES),
        "effort_units": [result.model.effort_unit(j) for j in JOINT_NAMES],
        "fitted_joints": [JOINT_NAMES[j] for j in wls.joints],
        "left_out": result.left_out,
        "data": result.data_extent(),
        "warnings": (result.effort_convention_warnings() + result.recording_warnings() + result.unrecorded_joint_warnings()
                     + result.overfit_warnings() + result.params_file_warnings()),
        "config": {
            "runs": list(cfg.runs), "holdout": list(cfg.holdout), "joints": list(cfg.joints),
            "friction_law": result.regressor.friction_law.describe(), "bounds_file": str(result.bounds.source),
            "prior": result.prior_source, "seed": cfg.seed, "solver": cfg.solver, "model_file": str(result.model.source),
        },
        "runs": {"train": [_run_entry(r, result) for r in result.train], "holdout": [_run_entry(r, result) for r in result.holdout]},
        "input_files": _input_files(result, reference),
        "versions": software_versions(),
        "processing": _processing(result),
        "presliding": {
            "definition": PRESLIDING_DEFINITION,
            "links": result.presliding_choice,
        },
        "definitions": DEFINITIONS,
        "errors": errors,
        "prior_errors_first_period": prior_errors,
        "reference": {
            "params_file": reference[1] if reference else None,
            "errors_whole_run": reference_errors["whole_run"],
            "errors_first_period": reference_errors["first_period"],
            "pseudo_inertia_smallest_eigenvalue_kg_m2": reference[2] if reference else None,
        },
        "condition_number": wls.condition_number,
        "condition_number_limit": MAX_CONDITION_NUMBER,
        "consistent_departure": _consistent_departure(result),
        "noise_sigma": wls.sigma.tolist(),
        "residual_autocorrelation_samples": wls.autocorrelation_samples.tolist(),
        "rank_tolerance": base.tolerance,
        "n_standard": len(result.regressor.layout),
        "n_base": len(base),
        **_parameter_entries(result),
        "convex_program": {
            "solver": result.consistent.solver, "status": result.consistent.status,
            "data_term": result.consistent.objective_data, "prior_term": result.consistent.objective_prior,
        },
        "timings_s": result.timings_s,
    }


def _parameter_entries(result: IdentificationResult) -> dict:
    """The base and standard parameters, which the data determine, and the masses against their bounds."""
    layout, base, wls, theta = result.regressor.layout, result.base, result.wls, result.theta
    units = parameter_units(result)
    reference = result.reference_theta if result.reference_theta is not None else np.full(len(theta), np.nan)
    held = ~np.isnan(reference)  # acting on no fitted joint: the reference's value, not the fit's
    return {
        "base_parameters": [
            {"name": name, "wls": float(b), "standard_error": float(s), "consistent": float(c)}
            for name, b, s, c in zip(base.names, wls.beta, wls.standard_errors, base.K @ theta)
        ],
        "standard_parameters": [
            {"name": n, "value": float(v), "unit": u, "identifiable": bool(i), "held_at_reference": bool(h),
             "prior": float(r if h else p)}  # a parameter held at the reference: its value's source
            for n, v, u, i, p, r, h in zip(layout.names, theta, units, base.identifiable, result.prior_theta, reference, held)
        ],
        "identifiable": [n for n, i in zip(layout.names, base.identifiable) if i],
        "set_by_constraints_and_prior": [n for n, i, h in zip(layout.names, base.identifiable, held) if not i and not h],
        "held_at_reference": [n for n, h in zip(layout.names, held) if h],
        "active_constraints": result.consistent.active,
        "pseudo_inertia_eigenvalues_kg_m2": pseudo_inertia_eigenvalues(result),
        "pseudo_inertia_margin_kg_m2": PSD_MARGIN_KG_M2,
        "masses_kg": {
            str(k): {"value": float(theta[layout.body_slice(k)][0]), "lower": result.bounds.mass_kg[k][0], "upper": result.bounds.mass_kg[k][1]}
            for k in layout.inertial_links
        },
    }


def covariance_document(result: IdentificationResult) -> dict:
    return {
        "format": COVARIANCE_FORMAT,
        "names": list(result.regressor.layout.names),
        "units": parameter_units(result),
        "nominal": result.theta.tolist(),
        "covariance": standard_covariance(result).tolist(),
        "frame": "m, m c and inertia about the link frame origin, link-frame axes (Pinocchio dynamic parameters)",
        "params_file": PARAMS_FILE,
        "friction_law": result.regressor.friction_law.describe(),
        "presliding": {str(k): d for k, d in result.regressor.friction_law.presliding},
        "basis": "weighted least squares on the base parameters, mapped with the minimum-norm inverse of K",
    }


# ------------------------------------------------------------------ html
def _figure_png(result: IdentificationResult, run: RunData, title: str) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = min(run.processed.first_period_samples(), len(run.processed))
    t = run.processed.t[:n] - run.processed.t[0]
    predicted = result.predicted(run)[:n]
    shown = [j for j, recorded in enumerate(run.processed.measured) if recorded]  # a joint not recorded has nothing to compare
    fig, axes = plt.subplots(len(shown), 1, figsize=(10, 1.9 * len(shown)), sharex=True, squeeze=False)
    for j, ax in zip(shown, axes[:, 0]):
        ax.plot(t, run.processed.tau[:n, j], color="#c0392b", lw=1.0, label="measured")
        ax.plot(t, predicted[:, j], color="#2c6fbb", lw=1.0, label="identified")
        ax.plot(t, predicted[:, j] - run.processed.tau[:n, j], color="k", lw=0.6, ls="--", label="difference")
        ax.set_ylabel(f"{JOINT_NAMES[j]} ({result.model.effort_unit(JOINT_NAMES[j])})")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(ncol=3, loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("t (s), first base period")
    fig.suptitle(title)
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=80)
    plt.close(fig)
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def _error_table(result: IdentificationResult, data: dict) -> str:
    rows = []
    reference = data["reference"]
    published = {name: {span: reference[f"errors_{span}"][name] for span in ("whole_run", "first_period")}
                 for name in reference.get("errors_first_period") or {}}
    for kind, runs in (("train", data["errors"]["train"]), ("held out", data["errors"]["holdout"]),
                       (f"held out, the reference parameters ({Path(reference['params_file'] or '').name})", published)):
        for name, entries in runs.items():
            for span, e in entries.items():
                cells = [text_cell(f"{name} ({kind}, {span.replace('_', ' ')})")]
                cells += [num_cell(v, run=name, quantity="relative_error", joint=j) for v, j in zip(e["relative_error"], JOINT_NAMES)]
                cells += [num_cell(v, run=name, quantity="rms", joint=j) for v, j in zip(e["rms"], JOINT_NAMES)]
                rows.append(cells)
    header = ["run"] + [f"rel {j}" for j in JOINT_NAMES] + [f"RMS {j} ({u})" for j, u in zip(JOINT_NAMES, data["effort_units"])]
    return table(header, rows)


def _consistent_departure(result: IdentificationResult) -> dict:
    """How far the physically consistent fit lies from the weighted least squares, in the latter's standard
    errors (largest over the base parameters): where it is many, the data and the constraints disagree and the
    standard errors, which leave out model error, say little of the final values' uncertainty."""
    distance = np.abs(result.base.K @ result.theta - result.wls.beta) / np.maximum(result.wls.standard_errors, 1e-300)
    worst = int(np.argmax(distance))
    return {"max_standard_errors": float(distance[worst]), "base_parameter": result.base.names[worst],
            "over_3_standard_errors": int(np.sum(distance > 3.0)), "of": len(distance)}


def html_page(result: IdentificationResult, data: dict) -> str:
    """identification.html (templates/identification.html): the errors, a figure per run, the bodies and parameters."""
    figures = [{"run": run.name, "label": label, "png": _figure_png(result, run, f"{run.name} ({label}): measured vs identified efforts")}
               for label, runs in (("training", result.train), ("held-out", result.holdout)) for run in runs]
    bodies = [[text_cell(f"link {key} ({result.model.links[int(key)].name})"), num_cell(m["value"]), num_cell(m["lower"]), num_cell(m["upper"]),
               num_cell(data["pseudo_inertia_eigenvalues_kg_m2"][key][0])] for key, m in data["masses_kg"].items()]
    standard = [[text_cell(p["name"]), num_cell(p["value"]), text_cell(p["unit"]), text_cell("yes" if p["identifiable"] else "held at the reference: acts on no fitted joint" if p.get("held_at_reference")
                                                     else "constraints and prior"),
                 num_cell(p["prior"])] for p in data["standard_parameters"]]
    base = [[text_cell(b["name"]), num_cell(b["wls"]), num_cell(b["standard_error"]), num_cell(b["consistent"])] for b in data["base_parameters"]]
    return render("identification.html", title="dvrk-dart identification", data=data, fmt=fmt, max_condition_number=MAX_CONDITION_NUMBER,
                  error_table=_error_table(result, data), figures=figures,
                  bodies_table=table(["link", "mass (kg)", "lower", "upper", "smallest pseudo-inertia eigenvalue (kg m^2)"], bodies),
                  standard_table=table(["parameter", "value", "unit", "identifiable alone", "prior"], standard),
                  base_table=table(["combination", "weighted LS", "standard error", "consistent fit"], base))


def write_outputs(result: IdentificationResult, folder: Path) -> dict:
    """Write the four files into `folder` (a folder being built); returns the summary."""
    folder = Path(folder)
    write_json_atomic(folder / PARAMS_FILE, params_json(result.theta, result.regressor.layout, result.model, result.regressor.friction_law))
    try:  # the file every --params reader will see: its own checks
        load_parameters(folder / PARAMS_FILE, result.model)
    except DvrkDartError as exc:  # name what the user asked for, not the folder being built
        message = str(exc).replace(str(folder / PARAMS_FILE), f"the identified {PARAMS_FILE}")
        fit = result.consistent
        hint = (f"the {fit.solver} solver ended '{fit.status}'" if fit.status != "optimal"
                else "check --bounds and --prior")
        raise DvrkDartError(f"identify: {message} ({hint})") from None
    data = summary(result)
    write_json_atomic(folder / COVARIANCE_FILE, covariance_document(result))
    write_text_atomic(folder / SUMMARY_FILE, json_text(data))
    write_text_atomic(folder / HTML_FILE, html_page(result, data))
    return data


def identify_into_folder(config: IdentificationConfig, out: str | Path) -> tuple[IdentificationResult, dict]:
    """The folder is checked before any work, built beside `out` and swapped in whole."""
    from dvrk_dart.io.outputs import building_folder, check_output_folder

    check_output_folder(out, "identification", writes=FOLDER_ENTRIES)
    result = identify(config)
    with building_folder(out, "identification") as folder:
        data = write_outputs(result, folder)
    return result, data


def report_section(*datas: dict) -> tuple[str, str]:
    """(title, html) of the validation report: the published parameters vs the
    project's own identification on each held-out run, per joint, once per
    processing (identification.json of each). Cells carry data-identification
    (not data-quantity: these are not analysis/metrics.csv rows) and data-processing."""
    parts = []
    for data in datas:
        processing, ref = data["processing"]["processing"], data["reference"]
        parts.append({"processing": processing, "runs": data["config"]["runs"], "n_base": data["n_base"], "condition_number": fmt(data["condition_number"]),
                      "worst": fmt(worst_eigenvalue(data)), "published_worst": fmt(ref["pseudo_inertia_smallest_eigenvalue_kg_m2"]),
                      "departure": data["consistent_departure"],
                      "tables": [(run, _holdout_table(run, own, ref["errors_first_period"].get(run), processing, data["effort_units"]))
                                 for run, own in data["errors"]["holdout"].items()]})
    return "Own identification vs the published parameters", render("sections/identification.html", parts=parts)


def _holdout_table(run: str, own: dict, published: dict | None, processing: str, units: list[str]) -> str:
    rows = []
    for j, name in enumerate(JOINT_NAMES):
        mine = own["first_period"]["relative_error"][j]
        theirs = published["relative_error"][j] if published else None
        ratio = mine / theirs if theirs else None
        css = "" if ratio is None else ("better" if ratio <= 1.0 else "worse")
        cell = {"run": run, "joint": name, "processing": processing}
        rows.append([text_cell(name), num_cell(theirs, identification="relative_error_published_params", **cell),
                     num_cell(mine, css=css, identification="relative_error_identified", **cell),
                     num_cell(ratio, identification="ratio_identified_to_published", **cell),
                     num_cell(own["first_period"]["rms"][j], identification="rms_identified", **cell), text_cell(units[j])])
    return table(["joint", "published params", "own identification", "ratio", "RMS own", "unit"], rows)


def worst_eigenvalue(data: dict) -> float:
    return min(min(v) for v in data["pseudo_inertia_eigenvalues_kg_m2"].values()) if data["pseudo_inertia_eigenvalues_kg_m2"] else math.inf
