"""What produced an output: software versions and the git revision."""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import os
import platform
import subprocess
from pathlib import Path

from dvrk_dart.paths import PACKAGE_DIR


def software_versions() -> dict[str, str | bool | None]:
    """Versions of what produced the run, so a log can be traced to its code (`git_dirty`: whether the
    package's tree had uncommitted changes, null where git cannot tell)."""
    versions = {"python": platform.python_version()}
    for label, dist in (
        ("numpy", "numpy"),
        ("dartpy", "dartpy"),
        ("pinocchio", "pin"),
        ("rerun-sdk", "rerun-sdk"),
        ("mcap", "mcap"),
        ("dvrk_dart", "dvrk-dart"),
    ):
        try:
            versions[label] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            versions[label] = "unknown"
    versions["git_revision"], versions["git_dirty"] = _git_state()
    return versions


@functools.lru_cache(maxsize=1)
def _git_state() -> tuple[str, bool | None]:
    """(HEAD revision, whether there are uncommitted changes, None if unknown) of the package's
    tree, read once per process: the code a process runs is the code it loaded."""
    here = PACKAGE_DIR

    def git(*args: str) -> str | None:
        try:
            # --no-optional-locks: `status` would refresh the index under .git/index.lock, which a
            # process ended mid-way (Ctrl-C, a timeout) left behind in the user's repository
            done = subprocess.run(["git", "--no-optional-locks", *args], cwd=here, capture_output=True, text=True, timeout=10)
        except (OSError, subprocess.SubprocessError):
            return None
        return done.stdout.strip() if done.returncode == 0 else None

    revision = git("rev-parse", "HEAD")
    if revision is None:
        return "unknown", None
    status = git("status", "--porcelain", "--untracked-files=no")
    return revision, None if status is None else bool(status)


def sha256_of(path: Path) -> str:
    """sha256 of a file; of a folder (a rosbag2 bag): of its files' relative names and contents."""
    digest = hashlib.sha256()
    path = Path(path)
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    for file in files:
        if path.is_dir():
            digest.update(file.relative_to(path).as_posix().encode() + b"\0")
        with open(file, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                digest.update(chunk)
    return digest.hexdigest()


def file_record(path: Path) -> dict[str, str]:
    """A file an output rests on (the identified parameters, ...): its path (absolute: a path relative to where the
    command ran names no file later) and content hash."""
    return {"path": os.path.abspath(path), "sha256": sha256_of(path)}


def arm_model_record(model) -> dict[str, str]:
    """The arm an output is of (a `PsmModel`): its model card's name, path and content hash."""
    return {"name": model.name, **file_record(model.source)}
