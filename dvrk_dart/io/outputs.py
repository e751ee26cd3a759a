"""Output folders: checked before any work, built beside their place and
swapped in whole at the end, and never replacing what the tool did not make.

A folder the tool makes (a run, a report, a diagnosis) holds a marker file
naming its kind. An existing `--out` may be replaced only when it is empty,
holds that marker, or (folders written before markers existed) holds nothing
but the files that kind of folder is made of.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import uuid
from collections.abc import Iterator
from pathlib import Path

from dvrk_dart.errors import DvrkDartError

MARKER = ".dvrk-dart"
#: what each kind of folder is made of (the legacy test, before markers)
KNOWN_ENTRIES = {
    "run": {"config.json", "metrics.json", "run.mcap", "run.rrd", "inputs.sha256"},
    "report": {"index.html", "analysis", "figures"},
    "uncertainty": {"uncertainty.json", "band.csv", "params", "figures"},
    "excitation": {"excitation.json"},
    "diagnosis": {"diagnosis.json", "diagnosis.html", "figures", "replay_before", "replay_after", "where.csv"},
    "identification": {"params.json", "params_covariance.json", "identification.json", "identification.html"},
}


def _nearest_existing(path: Path) -> Path:
    for candidate in (path, *path.parents):
        if candidate.exists() or candidate.is_symlink():
            return candidate
    return Path(".")


def check_writable_folder(path: str | os.PathLike, option: str = "--out") -> Path:
    """`path` is, or can be created as, a folder this process may write in."""
    path = Path(path)
    existing = _nearest_existing(path.absolute())
    if existing == path.absolute() and not path.is_dir():
        raise DvrkDartError(f"{option}: {path} is a file, not a folder")
    if existing != path.absolute() and not existing.is_dir():
        raise DvrkDartError(f"{option}: {path} is under {existing}, which is a file")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise DvrkDartError(f"{option}: {existing} is not writable")
    return path


def check_output_folder(path: str | os.PathLike, kind: str, option: str = "--out") -> Path:
    """The folder `path` can receive a `kind` folder (replacing only one the tool
    made): raise a one-line error otherwise. Checks only: call it before any work."""
    path = check_writable_folder(path, option)
    if path.is_dir() and not replaceable(path, kind):
        raise DvrkDartError(f"{option}: {path} exists and was not made by dvrk-dart as a {kind} folder: refusing to replace it")
    if path.is_dir() and not os.access(path.absolute().parent, os.W_OK | os.X_OK):
        raise DvrkDartError(f"{option}: {path.absolute().parent} is not writable")
    return path


def replaceable(path: Path, kind: str) -> bool:
    entries = {p.name for p in path.iterdir()}
    if not entries:
        return True
    if MARKER in entries:
        try:
            return (path / MARKER).read_text(encoding="utf-8").strip() == kind
        except (OSError, UnicodeDecodeError):
            return False
    return entries <= KNOWN_ENTRIES[kind]


@contextlib.contextmanager
def building_folder(target: str | os.PathLike, kind: str) -> Iterator[Path]:
    """Yield an empty folder beside `target`; on success it replaces `target` as
    a whole (marked as `kind`); on any failure or interruption `target` is left
    as it was and the partial folder is removed."""
    target = Path(target)
    check_output_folder(target, kind)
    target.parent.mkdir(parents=True, exist_ok=True)
    building = target.with_name(f".{target.name}.building-{os.getpid()}-{uuid.uuid4().hex[:8]}")
    building.mkdir()
    try:
        yield building
        (building / MARKER).write_text(kind + "\n", encoding="utf-8")
        swap_in(building, target)
    finally:
        if building.exists():
            shutil.rmtree(building, ignore_errors=True)


def swap_in(built: Path, target: Path) -> None:
    """Put the folder `built` at `target`, moving a previous one aside first so
    that there is always a complete folder at `target` or the old one."""
    old = None
    if target.exists():
        old = target.with_name(f".{target.name}.old-{uuid.uuid4().hex[:8]}")
        os.replace(target, old)
    os.replace(built, target)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def check_not_inside(inner: str | os.PathLike, outer: str | os.PathLike, inner_option: str, outer_option: str) -> None:
    """`outer` (an output that is replaced whole) may not contain `inner` (an input)."""
    inner_path, outer_path = Path(inner).resolve(), Path(outer).resolve()
    if inner_path == outer_path or outer_path in inner_path.parents:
        raise DvrkDartError(f"{outer_option}: {outer} contains {inner_option} {inner}: the output would replace its own input")
