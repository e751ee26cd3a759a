"""The `dvrk-dart` command line. Every user-facing error is one line on stderr
and exit code 2 (no traceback)."""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from .errors import DvrkDartError
from .joints import JOINT_NAMES, effort_unit


def _add_arm_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--params", help="identified parameters file (default: upstream params.json, resolved at run time)")


def cmd_model_errors(args: argparse.Namespace) -> int:
    """Per-joint relative and RMS error of the identified model on a measured run."""
    from .context import load_arm
    from .identified_model import parse_terms
    from .metrics import relative_error, rms
    from .reference_data import load_run, resolve_run
    from .signal import FIRST_PERIOD_SAMPLES, process

    arm = load_arm(params_file=args.params)
    terms = parse_terms(args.terms)
    processed = process(load_run(resolve_run(args.measured)))
    if args.first_period:
        processed = processed.head(FIRST_PERIOD_SAMPLES)
    predicted = arm.identified.predict(processed.q, processed.dq, processed.ddq, terms)
    result = {
        "relative_error": relative_error(predicted, processed.tau).tolist(),
        "rms": rms(predicted - processed.tau).tolist(),
        "samples": len(processed),
        "terms": args.terms,
    }
    if args.json:
        print(json.dumps(result))
    else:
        print(f"identified model ({args.terms}) vs {args.measured}: {result['samples']} samples")
        print(f"{'joint':>6} {'relative':>9} {'rms':>10}")
        for name, rel, r in zip(JOINT_NAMES, result["relative_error"], result["rms"]):
            print(f"{name:>6} {rel:9.4f} {r:10.4f} {effort_unit(name)}")
    return 0


def cmd_model_check(args: argparse.Namespace) -> int:
    """Print the model card facts: parameter oddities and basic model checks."""
    from .context import load_arm

    arm = load_arm(params_file=args.params)
    print(f"model: {arm.model.name} ({arm.model.source})")
    print(f"parameters: {arm.params.source}")
    for note in arm.params.oddities(arm.model):
        print(f"  oddity: {note}")
    q = np.zeros(len(JOINT_NAMES))
    print("g(0) =", np.array2string(arm.identified.gravity(q), precision=4))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="dvrk-dart", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("model-errors", help="errors of the identified model on a measured run")
    p.add_argument("--measured", required=True, help="measured run: path, or one|two|one-no-weight|one-105g")
    p.add_argument("--first-period", action="store_true", help="only the first base period (1111 samples), as upstream")
    p.add_argument("--terms", default="all", help="all | inertial | comma list of inertia,coriolis,gravity,friction,offset,spring,motor_inertia")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    _add_arm_options(p)
    p.set_defaults(func=cmd_model_errors)

    p = sub.add_parser("model-check", help="parameter oddities and model facts")
    _add_arm_options(p)
    p.set_defaults(func=cmd_model_check)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except DvrkDartError as exc:
        print(f"dvrk-dart: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("dvrk-dart: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
