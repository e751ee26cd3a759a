"""Monte Carlo over parameter uncertainty: is the measured effort already
inside what the identified parameters' uncertainty allows?

`dvrk-dart uncertainty --measured RUN --samples N --out DIR` draws N
physically consistent parameter sets (identification.sampling), replays the
run in DART (velocity mode) with each, on the chosen executor, and writes:

- uncertainty.json: how the sets were drawn, per joint the fraction of the
  measured samples inside the 5-95 % band of the simulated efforts, the RMS
  of the measured effort's distance to the band (0 inside: the gap that no
  parameter set within the uncertainty explains), and the fraction of the
  nominal model's efforts inside the band (a check of the band itself);
- band.csv: t, and per joint the band, the measured, the nominal simulated
  and the nominal model efforts; params/: every parameter set used;
- figures/band_<joint>.png: the measured efforts over the band.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.atomic import write_json_atomic
from dvrk_dart.io.outputs import building_folder, check_output_folder
from dvrk_dart.metrics import rms
from dvrk_dart.io.bags import BagTopics
from dvrk_dart.model.description import DEFAULT_MODEL_FILE, PsmModel
from dvrk_dart.model.joints import JOINT_NAMES
from dvrk_dart.runs.executors import run_tasks

#: the band: these quantiles of the simulated efforts over the samples
BAND_QUANTILES = (0.05, 0.95)


@dataclass(frozen=True)
class UncertaintyConfig:
    measured: str
    samples: int
    seed: int = 0
    relative_std: float | None = None
    params_cov: str | None = None
    duration_s: float | None = None
    dt_s: float = 1e-3
    dynamics: str = "identified"  # every identified term simulated: friction is uncertain too
    executor: str = "local"
    jobs: int = 2
    #: upstream | periodic | None: periodic where the run is periodic (`processing_of`)
    processing: str | None = None
    #: the arm's description file (--arm-model); workers load it themselves
    arm_model: str = str(DEFAULT_MODEL_FILE)
    #: how the measured run is read where it is a bag (--arm, --topic, --jaw-topic) or a CSV (--rate)
    topics: BagTopics = BagTopics()


def processing_of(config: UncertaintyConfig) -> tuple[str, str]:
    """(processing, why): with periodic processing the band, the measured and
    the model efforts are compared at the measured samples, each projected on
    the excitation's harmonics (a whole run only)."""
    from dvrk_dart.io.signal import process_all

    if config.processing == "periodic" and config.duration_s is not None:
        raise DvrkDartError("--duration with --processing periodic: a part of a run has no periodic projection of its own; "
                            "draw over the whole run, or give --processing upstream")
    if config.processing is not None:
        return config.processing, f"--processing {config.processing}"
    if config.duration_s is not None:
        return "upstream", "upstream: --duration replays a part of the run, which has no projection of its own"
    processed, note = process_all([_measured_run(config)], None)
    return processed[0].processing, note or "the run is a periodic excitation"


def _measured_run(config: UncertaintyConfig):
    from dvrk_dart.io.reference_data import load_run, resolve_run
    from dvrk_dart.model.model_file import load_model

    return load_run(resolve_run(config.measured), load_model(config.arm_model), config.topics)


def _replay(task: tuple[UncertaintyConfig, str, str]) -> dict:
    """Worker: the velocity replay with one parameter file -> its efforts
    (periodic: at the measured samples, in the measured efforts' band), on the
    arm of the config's model file."""
    from dvrk_dart.io.signal import process
    from dvrk_dart.runs.config import RunConfig
    from dvrk_dart.runs.replay import in_band_at_samples
    from dvrk_dart.runs.runner import run

    config, params_file, processing = task
    record = run(RunConfig("replay", "velocity", dynamics=config.dynamics, measured=config.measured, params_file=params_file,
                           duration_s=config.duration_s, dt_s=config.dt_s, processing=processing, arm_model=config.arm_model,
                           topics=config.topics))
    if "error" in record.metrics:
        raise DvrkDartError(record.metrics["error"])
    model = record.model_total(tuple(record.metrics["model_terms_compared"]))
    if processing == "upstream":
        return {"t": record.t, "sim": record.effort_sim, "measured": record.effort_measured, "model": model}
    processed = process(_measured_run(config), processing)
    return {"t": processed.t - processed.t[0], "sim": in_band_at_samples(processed, record.t, record.effort_sim),
            "measured": processed.tau, "model": in_band_at_samples(processed, record.t, model)}


def band_statistics(band_low: np.ndarray, band_high: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per joint: fraction of `values` inside [low, high], and the RMS of their distance to it."""
    outside = np.maximum(band_low - values, 0.0) + np.maximum(values - band_high, 0.0)
    return np.mean(outside == 0.0, axis=0), rms(outside)


def run_uncertainty(config: UncertaintyConfig, out: str | Path, ray_address: str | None = None) -> dict:
    from dvrk_dart.identification.sampling import sample_parameters
    from dvrk_dart.io.provenance import file_record, software_versions
    from dvrk_dart.io.reference_data import input_record, resolve_run
    from dvrk_dart.io.signal import process
    from dvrk_dart.io.arm import load_arm
    from dvrk_dart.runs.replay import replay_duration

    out = check_output_folder(out, "uncertainty")
    processing, processing_why = processing_of(config)
    # the run, its processing and the span: every input's error before any work
    replay_duration(process(_measured_run(config), processing), config.duration_s)
    start = time.perf_counter()
    arm = load_arm(config.arm_model)
    drawn = sample_parameters(arm, config.samples, config.seed, config.relative_std, config.params_cov)
    with building_folder(out, "uncertainty") as folder:
        (folder / "params").mkdir()
        paths = [folder / "params" / "nominal.json"] + [folder / "params" / f"sample_{i:04d}.json" for i in range(config.samples)]
        for path, params in zip(paths, [drawn.nominal, *drawn.samples]):
            path.write_text(json.dumps(params, indent=1))
        nominal, sims, failures = _replayed_samples(config, paths, processing, ray_address)
        low, high = np.quantile(sims, BAND_QUANTILES, axis=0)
        inside, gap = band_statistics(low, high, nominal["measured"])
        model_inside, _ = band_statistics(low, high, nominal["model"])
        recorded = _measured_run(config).measured_mask
        summary = {
            "config": asdict(config),
            "measured_file": {**input_record(resolve_run(config.measured), arm.model, config.topics), "replayed_s": float(nominal["t"][-1] - nominal["t"][0])},
            "versions": software_versions(),
            "processing": {"processing": processing, "chosen_because": processing_why},
            "parameters": drawn.source,
            # the file the nominal and the draws came from: a --params-cov file holds its own nominal (not the arm's --params)
            "params": file_record(Path(config.params_cov) if config.params_cov else arm.params.source),
            "projected_bodies": drawn.projected_bodies,
            "clipped_friction_coefficients": drawn.clipped_friction,
            "samples_replayed": len(sims),
            "failed_samples": failures,
            "band_quantiles": list(BAND_QUANTILES),
            "joints": list(JOINT_NAMES),
            "effort_units": [arm.model.effort_unit(j) for j in JOINT_NAMES],
            "recorded_joints": [j for j, on in zip(JOINT_NAMES, recorded) if on],
            "measured_inside_band_fraction": _recorded_only(inside, recorded),
            "rms_measured_outside_band": _recorded_only(gap, recorded),
            "nominal_model_inside_band_fraction": _recorded_only(model_inside, recorded),
            "band_width_rms": _recorded_only(rms(high - low), recorded),
            "rms_nominal_sim_vs_measured": _recorded_only(rms(nominal["sim"] - nominal["measured"]), recorded),
            "wall_time_s": time.perf_counter() - start,
        }
        write_json_atomic(folder / "uncertainty.json", summary)
        _write_band_csv(folder / "band.csv", nominal, low, high, recorded)
        plot_bands(folder / "band.csv", folder / "figures", arm.model, tuple(j for j, on in zip(JOINT_NAMES[:3], recorded) if on))
    return summary


def _replayed_samples(config: UncertaintyConfig, paths: list[Path], processing: str, ray_address: str | None):
    """The nominal replay, the samples' simulated efforts (samples, time, joint) and the failed replays' reasons."""
    results, failures = {}, {}
    tasks = [(config, str(p), processing) for p in paths]
    for task, result, error in run_tasks(_replay, tasks, config.executor, config.jobs, ray_address, desc="samples", unit="replay"):
        if error is None:
            results[Path(task[1]).name] = result
        else:
            failures[Path(task[1]).name] = error
    if "nominal.json" not in results:
        raise DvrkDartError(f"the nominal replay failed: {failures.get('nominal.json')}")
    sims = [r["sim"] for name, r in sorted(results.items()) if name != "nominal.json"]
    if len(sims) < 2:
        raise DvrkDartError(f"only {len(sims)} sample replay(s) succeeded: no band ({next(iter(failures.values()), '')})")
    return results["nominal.json"], np.stack(sims), failures


def _write_band_csv(path: Path, nominal: dict, low: np.ndarray, high: np.ndarray, recorded: np.ndarray) -> None:
    """The band per joint; a joint the run did not record has an empty measured column (it read 0.0)."""
    columns = {"t": nominal["t"]}
    for j, name in enumerate(JOINT_NAMES):
        measured = nominal["measured"][:, j] if recorded[j] else np.full(len(nominal["t"]), np.nan)
        columns |= {f"{name}_band_low": low[:, j], f"{name}_band_high": high[:, j], f"{name}_measured": measured,
                    f"{name}_nominal_sim": nominal["sim"][:, j], f"{name}_nominal_model": nominal["model"][:, j]}
    pd.DataFrame(columns).to_csv(path, index=False)


def _recorded_only(values: np.ndarray, recorded: np.ndarray) -> list:
    """Per joint, None where the run did not record the joint: no figure on it."""
    return [float(v) if on else None for v, on in zip(values, recorded)]


def plot_bands(band_csv: Path, folder: Path, model: PsmModel, joints: tuple[str, ...] = JOINT_NAMES[:3]) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    band = pd.read_csv(band_csv)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for name in joints:
        fig, ax = plt.subplots(figsize=(9, 3))
        ax.fill_between(band.t, band[f"{name}_band_low"], band[f"{name}_band_high"], color="tab:red", alpha=0.3,
                        label=f"simulated, {BAND_QUANTILES[0]:.0%}-{BAND_QUANTILES[1]:.0%} over the parameter samples")
        ax.plot(band.t, band[f"{name}_measured"], color="k", lw=0.8, label="measured")
        ax.plot(band.t, band[f"{name}_nominal_model"], color="tab:blue", lw=0.8, ls="--", label="identified model (nominal)")
        ax.set_xlabel("t (s)")
        ax.set_ylabel(f"{name} effort ({model.effort_unit(name)})")
        ax.legend(fontsize=7, loc="upper right")
        fig.tight_layout()
        path = folder / f"band_{name}.png"
        fig.savefig(path, dpi=90)
        plt.close(fig)
        paths.append(path)
    return paths
