"""What a command's parsed options say about its arm and its measured runs:
the arm model (--arm-model), the arm with its parameters (--params), and how
runs are read (--arm, --topic, --jaw-topic, --rate). Each command passes
them on explicitly; nothing is kept in ambient state."""

from __future__ import annotations

import argparse
from pathlib import Path


def arm_model_file(args: argparse.Namespace) -> Path:
    """The command's arm: its --arm-model, else the PSM."""
    from dvrk_dart.model.description import DEFAULT_ARM, resolve_arm_model

    return resolve_arm_model(getattr(args, "arm_model", None) or DEFAULT_ARM)


def command_arm(args: argparse.Namespace):
    """The command's arm (`arm_model_file`) with its --params, if the command takes them."""
    from dvrk_dart.io.arm import load_arm

    return load_arm(arm_model_file(args), getattr(args, "params", None))


def reading_options(args: argparse.Namespace):
    """How the command reads measured runs that are bags (--arm, --topic, --jaw-topic) or CSVs (--rate)."""
    from dvrk_dart.io.bags import BagTopics

    if not hasattr(args, "jaw_topic"):
        return BagTopics()
    return BagTopics(args.arm, args.topic, args.jaw_topic, args.rate)
