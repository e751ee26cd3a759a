"""The checks of single option values (argparse types): each refuses a bad
value in one line naming it, before any work (cli_parser.py uses them)."""

from __future__ import annotations

import argparse
import errno
import math
import os
import re
from pathlib import Path

from dvrk_dart.model.card_checks import ARM_NAMESPACE
from dvrk_dart.runs.config import MAX_DURATION_S


def non_empty(text: str) -> str:
    """An argparse type: any text but an empty one (an empty name would fall back to the default silently)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty value (leave the option out for its default)")
    return text


def arm_namespace(text: str) -> str:
    """A ROS namespace of one name (PSM1, MTML): letters, digits, underscores, a letter first."""
    if not re.fullmatch(ARM_NAMESPACE, text):
        raise argparse.ArgumentTypeError(f"'{text}' is not an arm's namespace (a ROS name such as PSM1: letters, digits, _)")
    return text


def int_at_least(low: int):
    """An argparse type: a whole number >= low."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"{value}: at least {low}")
        return value

    return parse


positive_int = int_at_least(1)


def int_in(low: int, high: int, why: str):
    """An argparse type: a whole number in [low, high], `why` saying where the top comes from."""
    at_least = int_at_least(low)

    def parse(text: str) -> int:
        value = at_least(text)
        if value > high:
            raise argparse.ArgumentTypeError(f"{value}: at most {high} ({why})")
        return value

    return parse


#: parameter sets of an uncertainty band: its 5-95 % quantiles settle within a
#: few hundred draws, and each draw is a whole replay
MAX_SAMPLES = 10000


def measured_run(text: str) -> str:
    """A measured run's name or path, checked for what the name alone tells
    (the file's content is checked when it is read)."""
    from dvrk_dart.io.reference_data import RUNS, manifest

    if not text.strip():
        raise argparse.ArgumentTypeError("an empty name (one, two, ... or a path)")
    if text in RUNS or text in manifest()["files"]:
        return text
    path = _looked_up(text)
    if path.is_symlink() and not path.exists():
        raise argparse.ArgumentTypeError(f"{text}: a broken symbolic link (to {os.readlink(path)})")
    if not path.exists():
        raise argparse.ArgumentTypeError(f"{text}: file not found, and not a reference run ({', '.join(RUNS)})")
    if not (path.is_file() or path.is_dir()):
        raise argparse.ArgumentTypeError(f"{text}: not a regular file (a CSV or a ROS bag)")
    return text


def existing_file(text: str) -> str:
    """A file that must exist (a commanded excitation: no reference run stands for one)."""
    path = _looked_up(text)
    if not path.exists():
        raise argparse.ArgumentTypeError(f"{text}: file not found")
    if not path.is_file():
        raise argparse.ArgumentTypeError(f"{text}: a folder, not a file")
    return text


def _looked_up(text: str) -> Path:
    """The path, once the system can look it up: a folder on the way that may not be searched, or a name too
    long, is one line (Path.exists raised them)."""
    path = Path(text)
    try:
        path.stat()
    except (FileNotFoundError, NotADirectoryError):
        pass  # said by the checks that follow
    except OSError as exc:
        if exc.errno != errno.ELOOP:  # a symbolic link's loop is said as a broken link
            raise argparse.ArgumentTypeError(f"{text}: {exc.strerror or exc}") from None
    return path


def number_in(low: float, high: float, unit: str = "", open_low: bool = False, open_high: bool = False):
    """An argparse type: a finite number in [low, high] (an end excluded when open)."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
        above = value > low if open_low else value >= low
        below = value < high if open_high else value <= high
        if not (math.isfinite(value) and above and below):
            interval = f"{'(' if open_low else '['}{low:g}, {high:g}{')' if open_high else ']'}"
            raise argparse.ArgumentTypeError(f"{text}: must be in {interval} {unit}".rstrip())
        return value

    return parse


def seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
    if not 0 <= value < 2**32:
        raise argparse.ArgumentTypeError(f"{value}: a seed is a whole number in [0, 2^32)")
    return value


#: rates a dVRK recording or command stream can have (its controllers run at most at a few kHz)
RATE_HZ = number_in(1.0, 1e4, "Hz")
SECONDS = number_in(0.0, MAX_DURATION_S, "s", open_low=True)
