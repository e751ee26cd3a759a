"""Atomic writes: an interrupted run never leaves a file that looks complete."""

from __future__ import annotations

import contextlib
import json
import os
import uuid
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from dvrk_dart.errors import raise_if_interrupted


def _jsonable(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path next to `path`; move it onto `path` only on success.

    A crash or an exception midway leaves the previous file (or none) in place,
    never a truncated output that a later stage would read as complete.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    # a fresh name rather than mkstemp: the writer creates the file with the
    # usual permissions (mkstemp's are 0600)
    tmp = target.with_name(f".{target.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.partial")
    try:
        yield tmp
        raise_if_interrupted()
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)


def strict_json(value):
    """`value` with every non-finite number (NaN, inf) replaced by None: JSON
    has no NaN, and a missing value is null."""
    if isinstance(value, dict):
        return {k: strict_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [strict_json(v) for v in value]
    if isinstance(value, np.ndarray):
        return strict_json(value.tolist())
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    return value


def json_text(data) -> str:
    """Strict JSON (null for missing values), indented, with a final newline."""
    return json.dumps(strict_json(data), indent=2, default=_jsonable, allow_nan=False) + "\n"


def write_json_atomic(target: str | os.PathLike, data) -> None:
    with atomic_path(target) as tmp:
        tmp.write_text(json_text(data))


def write_text_atomic(target: str | os.PathLike, text: str) -> None:
    with atomic_path(target) as tmp:
        tmp.write_text(text)
