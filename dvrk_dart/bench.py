"""`make bench`: performance figures against their targets, printed with ratios
and written to out/bench.json. Targets live here, not in timed tests."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.atomic import write_json_atomic
from dvrk_dart.io.outputs import check_shared_folder, mark_written
from dvrk_dart.pipeline import VALIDATION_KIND
from dvrk_dart.io.reference_data import load_run, resolve_run, sample_rate_hz
from dvrk_dart.io.signal import central_difference
from dvrk_dart.io.arm import load_arm
from dvrk_dart.model.description import DEFAULT_MODEL_FILE
from dvrk_dart.model.model_file import load_model

#: (key, target, "lower" if smaller is better else "higher", unit, what the target stands for)
TARGETS = {
    "model_query_us": (6.0, "lower", "µs", "one query of M, C·dq and g (CoppeliaSim's C++ library: 6-7 µs)"),
    "model_batch_ms": (50.0, "lower", "ms", "all model efforts of a 5999-sample run"),
    "sim_realtime_factor": (20.0, "higher", "x", "simulated s per wall s, full closed-chain arm with counterweight at 1 ms"),
    "validate_s": (420.0, "lower", "s", "make validate on this machine: every stage and the report (the last one run, validate.json)"),
    "diagnose_s": (60.0, "lower", "s", "diagnosis of one 30 s run, re-simulation included"),
    "identify_s": (60.0, "lower", "s", "identification from one 30 s run, outputs written (dvrk-dart identify --runs one)"),
    "mc_runs_per_s": (1.0, "higher", "1/s", "Monte Carlo replays of a 5 s run per second (dvrk-dart uncertainty, local executor, 2 workers)"),
    "diagnose_three_s": (120.0, "lower", "s", "diagnosis of three 30 s runs at once (two payload runs and their baseline), re-simulation included"),
    "bag_import_s": (1.0, "lower", "s", "read a 30 s, 200 Hz two-topic ROS 2 bag (MCAP) as a measured run"),
    "periodic_projection_s": (0.2, "lower", "s", "the periodic layer on one 30 s run: period, cutoff, projection of q and efforts, noise; best of 5"),
    "force_estimation_s": (0.5, "lower", "s", "the force at the instrument from a 30 s run's effort gap: Jacobians and F = J^-T tau per sample; best of 5"),
    "replay_realtime_factor": (20.0, "higher", "x", "dvrk-dart replay --measured two end to end (28 s, logs written), imports excluded, best of 3"),
}

#: figures printed beside the targets, without one of their own
BESIDE = {
    "mc_runs_per_s_ray": ("1/s", "mc_runs_per_s on a local Ray instance started with 2 CPUs (its start-up included)"),
    "replay_realtime_factor_median": ("x", "the median of the replays replay_realtime_factor is the best of"),
    "replay_realtime_factor_cpu": ("x", "the best replay per CPU second of this process"),
    "campaign_runs_s": ("s", "the simulation runs of the last make validate alone (campaign.json)"),
}


def best_time(fn, repeat: int, number: int) -> float:
    """Best mean time of `number` calls over `repeat` rounds (s per call)."""
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - start) / number)
    return best


def bench_model() -> dict:
    arm = load_arm(DEFAULT_MODEL_FILE)
    q = np.array([0.1, 0.2, 0.1, 0.3, 0.2, -0.1, 0.4])
    dq = np.full(7, 0.1)
    query = best_time(lambda: arm.identified.mcg(q, dq), repeat=5, number=5000)
    run = load_run(resolve_run("two"), arm.model)
    q_all, dq_all = run.q, run.dq
    ddq_all = central_difference(dq_all, 1.0 / sample_rate_hz())
    batch = best_time(lambda: arm.identified.predict(q_all, dq_all, ddq_all), repeat=3, number=1)
    return {"model_query_us": query * 1e6, "model_batch_ms": batch * 1e3, "model_batch_samples": len(run)}


def bench_periodic(repeat: int = 5) -> dict:
    from dvrk_dart.io.periodic import analyse

    run = load_run(resolve_run("two"), load_model(DEFAULT_MODEL_FILE))
    analyse(run.t, run.q, run.tau, sample_rate_hz(), "two")  # warm-up
    return {"periodic_projection_s": best_time(lambda: analyse(run.t, run.q, run.tau, sample_rate_hz(), "two"), repeat=repeat, number=1)}


def bench_force(repeat: int = 5) -> dict:
    from dvrk_dart.model.force import estimate_force

    arm = load_arm(DEFAULT_MODEL_FILE)
    run = load_run(resolve_run("two"), arm.model)
    ddq = central_difference(run.dq, 1.0 / sample_rate_hz())
    gap = run.tau - arm.identified.predict(run.q, run.dq, ddq)
    return {"force_estimation_s": best_time(lambda: estimate_force(arm.model, run.q, gap), repeat=repeat, number=1)}


def bench_simulation() -> dict:
    from dvrk_dart.sim.realtime import measure_realtime_factor

    return {"sim_realtime_factor": measure_realtime_factor(load_model(DEFAULT_MODEL_FILE))}


def bench_campaign(out_dir: Path) -> dict:
    """The times the last `make validate` recorded: the whole of it (validate.json, a completed run's only) and its
    simulation runs (campaign.json)."""
    figures = {}
    for key, name in (("validate_s", "validate.json"), ("campaign_runs_s", "campaign.json")):
        summary = json.loads((out_dir / name).read_text()) if (out_dir / name).is_file() else {}
        if summary.get("completed", True) and summary.get("wall_time_s") is not None:
            figures[key] = summary["wall_time_s"]
    return figures


def bench_diagnosis() -> dict:
    from dvrk_dart.diagnosis.checks.validation import benchmark_diagnosis

    return {"diagnose_s": benchmark_diagnosis(), "diagnose_three_s": benchmark_diagnosis(("one-105g", "one-105g-half"), "one-no-weight")}


def bench_identification() -> dict:
    """`identify --runs one` end to end: processing, regressor, fits and the four files."""
    import tempfile

    from dvrk_dart.identification.identify import IdentificationConfig, identify
    from dvrk_dart.identification.outputs import write_outputs

    with tempfile.TemporaryDirectory() as folder:
        start = time.perf_counter()
        write_outputs(identify(IdentificationConfig(runs=("one",))), Path(folder))
        return {"identify_s": time.perf_counter() - start}


def bench_monte_carlo(samples: int = 8) -> dict:
    """`dvrk-dart uncertainty` end to end (sampling, replays, band, files) on each executor."""
    import tempfile

    from dvrk_dart.runs.uncertainty import UncertaintyConfig, run_uncertainty

    figures = {}
    for executor, key in (("local", "mc_runs_per_s"), ("ray", "mc_runs_per_s_ray")):
        config = UncertaintyConfig(measured="two", samples=samples, relative_std=0.05, duration_s=5.0, executor=executor, jobs=2)
        with tempfile.TemporaryDirectory() as folder:
            start = time.perf_counter()
            run_uncertainty(config, Path(folder) / "mc")
            figures[key] = (samples + 1) / (time.perf_counter() - start)  # the nominal replay counts too
    return figures


def bench_bag_import() -> dict:
    """A 30 s, 200 Hz bag of the two PSM topics (made from run "two"), read back."""
    import tempfile

    from dvrk_dart.io.bag_writer import arm_joint_states, write_bag
    from dvrk_dart.io.bags import load_bag_run

    model = load_model(DEFAULT_MODEL_FILE)
    run = load_run(resolve_run("two"), model)
    with tempfile.TemporaryDirectory() as folder:
        bag = write_bag(Path(folder) / "two", arm_joint_states(model, "PSM1", run.t, run.q, run.dq, run.tau))
        seconds = best_time(lambda: load_bag_run(bag, model), repeat=3, number=1)
    return {"bag_import_s": seconds}


def bench_replay(repeat: int = 3) -> dict:
    """`dvrk-dart replay --measured two --out TMP` through the CLI's own entry point:
    run config, simulation, identified model, config.json, metrics.json, run.mcap and
    run.rrd. The modules it loads are imported first (a process pays that once); what a
    process keeps of a run it read (its parse, its periodic analysis) is dropped before each.
    The best of `repeat` replays, as the other timings (this machine is shared: its
    speed varies by a fifth from one second to the next); the median and the rate
    per CPU second of the best are recorded beside it."""
    import contextlib
    import io
    import tempfile

    import dvrk_dart.io.mcap_log  # noqa: F401  (imports, not timed)
    import dvrk_dart.io.rerun_log  # noqa: F401
    import dvrk_dart.runs.replay  # noqa: F401
    from dvrk_dart import cli

    from dvrk_dart.io.reference_data import forget_read_runs

    rates = []
    with tempfile.TemporaryDirectory() as folder, contextlib.redirect_stdout(io.StringIO()):
        for i in range(repeat):
            forget_read_runs()  # each replay parses and analyses its run, as a process of its own does
            out = Path(folder) / f"replay-two-{i}"
            wall, cpu = time.perf_counter(), time.process_time()
            code = cli.main(["replay", "--measured", "two", "--out", str(out)])
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            if code != 0 or not all((out / name).is_file() for name in ("run.mcap", "run.rrd", "config.json", "metrics.json")):
                raise DvrkDartError(f"dvrk-dart replay --measured two failed (exit {code})")
            simulated = json.loads((out / "metrics.json").read_text())["duration_s"]
            rates.append((simulated / wall, simulated / cpu))
    best = max(rates)
    return {"replay_realtime_factor": best[0], "replay_realtime_factor_cpu": best[1],
            "replay_realtime_factor_median": float(np.median([r[0] for r in rates]))}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", default="out/bench.json")
    args = parser.parse_args(argv)
    out = Path(args.out)
    check_shared_folder(out.parent, VALIDATION_KIND)  # make validate's --out: the bench's file is one of its own
    figures = {}
    # the in-process timings first, then the end-to-end replay: nothing else (Ray's daemons, worker pools, a replay's
    # log writers) runs beside them yet (after the replay, one model query read 10.3 µs where alone it reads 6.7)
    try:
        for part in (bench_model, bench_periodic, bench_force, bench_replay, bench_simulation, lambda: bench_campaign(out.parent),
                     bench_diagnosis, bench_identification, bench_monte_carlo, bench_bag_import):
            figures.update(part())
    except DvrkDartError as exc:  # a failed command's own line (no reference data, say) is printed above it
        print(f"bench: {exc}", file=sys.stderr)
        return 2
    print(f"{'figure':<29} {'value':>10} {'target':>8}  {'ratio':>6}  meaning")
    for key, (target, sense, unit, meaning) in TARGETS.items():
        value = figures.get(key)
        if value is None:
            print(f"{key:<29} {'-':>10} {target:>8g}  {'':>6}  {meaning} (not measured)")
            continue
        ratio = target / value if sense == "lower" else value / target
        figures[f"{key}_target"] = target
        verdict = "ok" if ratio >= 1 else "MISSED"
        print(f"{key:<29} {value:10.3f} {target:>8g}  {ratio:6.2f}  {unit}: {meaning} [{verdict}]")
    for key, (unit, meaning) in BESIDE.items():
        if key in figures:
            print(f"{key:<29} {figures[key]:10.3f} {'-':>8}  {'':>6}  {unit}: {meaning}")
    write_json_atomic(out, figures)
    mark_written(out.parent, VALIDATION_KIND, out.name)
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
