"""Output folders: checked before any work, built beside their place and
swapped in whole at the end, and never replacing what the tool did not make.

A folder the tool makes (a run, a report, a diagnosis) holds a marker file
naming its kind and every file it wrote, with checksums. An existing `--out`
may be replaced only when it is empty or holds that marker; replacing it
replaces only the files the marker lists *with their listed content*: anything
else (a plot a user put in figures/, notes, a file the user edited since) is
carried into the new folder as it is, and where the new output would write a
file of the same name the command is refused. A symbolic link is never
replaced. Half-built folders of processes that no longer run are removed.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import re
import shutil
import signal
import stat
import threading
import uuid
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

from dvrk_dart.errors import DvrkDartError, raise_if_interrupted
from dvrk_dart.io.provenance import sha256_of

MARKER = ".dvrk-dart"


@dataclass(frozen=True)
class Marker:
    """What the tool wrote in a folder: its kind and every file (relative path -> sha256)."""

    kind: str
    files: dict[str, str]

    def owns(self, folder: Path, relative: str) -> bool:
        """The tool wrote this file and nobody changed it since (a marker can be
        copied or forged: only the content's checksum proves the file is ours)."""
    
        path = folder / relative
        if relative not in self.files or path.is_symlink() or not path.is_file():
            return False
        try:
            return sha256_of(path) == self.files[relative]
        except OSError:
            return False


def read_marker(folder: Path) -> Marker | None:
    path = folder / MARKER
    if not path.is_file() or path.is_symlink():
        return None
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    try:
        raw = json.loads(text)
    except json.JSONDecodeError:  # an earlier version's marker (its kind only) proves nothing
        return None
    if not isinstance(raw, dict) or not isinstance(raw.get("kind"), str) or not isinstance(raw.get("files"), dict):
        return None
    return Marker(raw["kind"], {str(k): str(v) for k, v in raw["files"].items()})


def _files(folder: Path, skip_marked: bool = False) -> list[str]:
    """Relative paths of every file, symlink and empty folder below `folder`
    (links not followed), the marker excluded; with `skip_marked`, not those
    of sub-folders that hold their own marker."""
    out = []
    for root, dirs, files in os.walk(folder):
        base = Path(root)
        if skip_marked:
            dirs[:] = [d for d in dirs if not (base / d / MARKER).is_file() or (base / d).is_symlink()]
        if not dirs and not files and base != folder:
            out.append(base.relative_to(folder).as_posix())
        for name in files + [d for d in dirs if (base / d).is_symlink()]:
            relative = (base / name).relative_to(folder).as_posix()
            if relative != MARKER:
                out.append(relative)
    return sorted(out)


def write_marker(folder: Path, kind: str, skip_marked: bool = False) -> None:
    """The marker of a folder the tool built: its kind and what it wrote, with checksums."""
    files = {relative: sha256_of(folder / relative) for relative in _files(folder, skip_marked) if (folder / relative).is_file()}
    (folder / MARKER).write_text(json.dumps({"kind": kind, "files": files}, indent=1) + "\n", encoding="utf-8")


def mark_written(folder: Path, kind: str, relative: str) -> None:
    """One more file the tool wrote in a `kind` folder, added to its marker (made when the folder has none): a
    later command of that kind finds it its own (make validate refused the out/ that make bench wrote bench.json in)."""
    marker = read_marker(folder) or Marker(kind, {})
    files = {**marker.files, relative: sha256_of(folder / relative)}
    (folder / MARKER).write_text(json.dumps({"kind": marker.kind, "files": files}, indent=1) + "\n", encoding="utf-8")


def _nearest_existing(path: Path) -> Path:
    for candidate in (path, *path.parents):
        if candidate.exists() or candidate.is_symlink():
            return candidate
    return Path(".")


def _article(word: str) -> str:
    return "an" if word[:1] in "aeiou" else "a"


def check_writable_folder(path: str | os.PathLike, option: str = "--out") -> Path:
    """`path` is, or can be created as, a folder this process may write in."""
    path = Path(path)
    existing = _nearest_existing(path.absolute())
    if existing == path.absolute() and path.is_symlink() and not path.exists():
        raise DvrkDartError(f"{option}: {path} is a symbolic link to a missing {os.readlink(path)} (give the folder itself)")
    if existing == path.absolute() and not path.is_dir():
        raise DvrkDartError(f"{option}: {path} is a file, not a folder")
    if existing != path.absolute() and not existing.is_dir():
        raise DvrkDartError(f"{option}: {path} is under {existing}, which is a file")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise DvrkDartError(f"{option}: {existing} is not writable")
    return path


def check_output_folder(path: str | os.PathLike, kind: str, option: str = "--out", writes: Iterable[str] = ()) -> Path:
    """The folder `path` can receive a `kind` folder (replacing only one the tool
    made; `writes`: files it may write, relative, which no file of the user's
    may hold): raise a one-line error otherwise. Checks only: call it before any work."""
    path = check_writable_folder(path, option)
    if path.is_symlink():
        raise DvrkDartError(f"{option}: {path} is a symbolic link: give the folder it points to, or a new name")
    whole = normalised(path)
    owner = enclosing_output(path)
    if owner is not None:
        raise DvrkDartError(f"{option}: {path} is part of {owner}, an output of dvrk-dart, which replacing it would break: "
                            f"give another folder (a new name inside {owner} is fine)")
    if whole == Path.cwd() or whole in Path.cwd().parents:
        raise DvrkDartError(f"{option}: {path} is the current folder or holds it: give a folder beside or below it")
    if len(os.fsencode(whole.name)) + BUILDING_SUFFIX_BYTES > NAME_MAX_BYTES:
        raise DvrkDartError(f"{option}: the name {whole.name[:20]}... is too long (at most {NAME_MAX_BYTES - BUILDING_SUFFIX_BYTES} bytes)")
    if path.is_dir() and not replaceable(path, kind):
        raise DvrkDartError(f"{option}: {path} exists and was not made by dvrk-dart as {_article(kind)} {kind} folder: refusing to replace it")
    edited = _edited_files(path) if path.is_dir() else []
    if edited:  # the new output may write that file: say so now, not after the work
        raise DvrkDartError(f"{option}: {path / edited[0]} was written by dvrk-dart and changed since: move it, then run again")
    in_the_way = [found for found in (_users_path(path, name) for name in writes) if found] if path.is_dir() else []
    if in_the_way:  # found at the end, it would cost the whole work
        raise DvrkDartError(f"{option}: {path / in_the_way[0]} is yours and the new output may write there: move it, then run again")
    if path.is_dir() and not os.access(path.absolute().parent, os.W_OK | os.X_OK):
        raise DvrkDartError(f"{option}: {path.absolute().parent} is not writable")
    return path


def check_shared_folder(path: str | os.PathLike, kind: str, option: str = "--out") -> Path:
    """A folder several stages fill in place (`validate --out`: runs, the
    diagnosis, the identification): new, empty, or marked as `kind` with every
    file the marker does not vouch for inside a sub-folder of its own marker.
    Call `write_marker(path, kind, skip_marked=True)` once it is ours."""
    path = check_writable_folder(path, option)
    if path.is_symlink():
        raise DvrkDartError(f"{option}: {path} is a symbolic link: give the folder it points to, or a new name")
    if not path.is_dir() or not any(path.iterdir()):
        return path
    marker = read_marker(path)
    if marker is None or marker.kind != kind:
        raise DvrkDartError(f"{option}: {path} exists and was not made by dvrk-dart as {_article(kind)} {kind} folder: refusing to write in it")
    foreign = [relative for relative in _files(path, skip_marked=True)
               if not marker.owns(path, relative) and not (path / relative).is_dir()]  # an empty folder holds nothing to lose
    if foreign:
        raise DvrkDartError(f"{option}: {path / foreign[0]} is not what dvrk-dart wrote there (a file of yours, or one changed since): "
                            "move it, then run again")
    return path


#: a file name's longest length on the usual file systems, and what the
#: half-built folder's name adds to the output's (.NAME.building-PID-HEX)
NAME_MAX_BYTES = 255
BUILDING_SUFFIX_BYTES = 40


def normalised(path: str | os.PathLike) -> Path:
    """The absolute path with `..` and `.` resolved by name (`r7/../r7` is
    `r7`: once the folder is moved aside, `r7/..` no longer exists)."""
    return Path(os.path.normpath(Path(path).absolute()))


def enclosing_output(path: str | os.PathLike) -> Path | None:
    """The nearest folder above `path` (links resolved) whose marker lists it
    or a file under it (a diagnosis's replay_before/, a run's config.json):
    replacing `path` would break that output."""
    path = Path(path).resolve()
    for parent in path.parents:
        marker = read_marker(parent)
        if marker is not None:
            inside = path.relative_to(parent).as_posix()
            if any(relative == inside or relative.startswith(inside + "/") for relative in marker.files):
                return parent
    return None


def _edited_files(folder: Path) -> list[str]:
    """The files the folder's marker lists that are no longer as the tool wrote them."""
    marker = read_marker(folder)
    if marker is None:
        return []
    return [relative for relative in marker.files if (folder / relative).exists() and not marker.owns(folder, relative)]


def _users_path(folder: Path, relative: str) -> str | None:
    """The first path to `relative` (a parent folder, or the file) that something of the user's holds, else None."""
    marker = read_marker(folder)
    parts = Path(relative).parts
    for k in range(1, len(parts) + 1):
        sub = Path(*parts[:k])
        if (folder / sub).is_symlink() or ((folder / sub).exists() and (k == len(parts) or not (folder / sub).is_dir())):
            return None if marker is not None and marker.owns(folder, str(sub)) else str(sub)
    return None


def replaceable(path: Path, kind: str) -> bool:
    """Empty, or marked by the tool as a `kind` folder."""
    if not any(path.iterdir()):
        return True
    marker = read_marker(path)
    return marker is not None and marker.kind == kind


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


#: the file every half-built folder holds from its first instant: only such folders are ever removed as stale
BUILDING_SENTINEL = ".dvrk-dart-building"
#: the output folders this process has put in place, in order (a command stopped later names them: they are complete)
FOLDERS_WRITTEN: list[Path] = []


def remove_stale_building(target: Path) -> None:
    """Half-built folders of `target` left by processes killed hard (hidden:
    .NAME.building-PID-HEX, holding the sentinel; a user's folder of a like
    name is not one of them)."""
    pattern = re.compile(rf"\.{re.escape(target.name)}\.building-(\d+)-[0-9a-f]{{8}}")
    for candidate in target.parent.glob(f".{target.name}.building-*"):
        match = pattern.fullmatch(candidate.name)
        if (match and int(match.group(1)) != os.getpid() and not _process_alive(int(match.group(1)))
                and candidate.is_dir() and not candidate.is_symlink() and (candidate / BUILDING_SENTINEL).is_file()):
            shutil.rmtree(candidate, ignore_errors=True)
    _remove_stale_old(target)


def _remove_stale_old(target: Path) -> None:
    """Previous folders of `target` moved aside by a swap that was cut short
    (.NAME.old-HEX): removed when they hold nothing, or only what their marker
    vouches for (a user's file in one is never removed)."""
    pattern = re.compile(rf"\.{re.escape(target.name)}\.old-[0-9a-f]{{8}}")
    for candidate in target.parent.glob(f".{target.name}.old-*"):
        if not pattern.fullmatch(candidate.name) or not candidate.is_dir() or candidate.is_symlink():
            continue
        marker = read_marker(candidate) or Marker("", {})
        if all(((candidate / r).is_dir() and not (candidate / r).is_symlink()) or marker.owns(candidate, r) for r in _files(candidate)):
            shutil.rmtree(candidate, ignore_errors=True)


@contextlib.contextmanager
def building_folder(target: str | os.PathLike, kind: str) -> Iterator[Path]:
    """Yield an empty folder beside `target`; on success it replaces `target`
    (marked as `kind`, with the user's own files of the old folder carried
    over); on any failure or interruption `target` is left as it was and the
    partial folder is removed."""
    check_output_folder(target, kind)
    target = normalised(target)
    building = target.with_name(f".{target.name}.building-{os.getpid()}-{uuid.uuid4().hex[:8]}")
    try:
        with signals_held():  # a Ctrl-C right after mkdir would leave the folder outside the try
            try:
                target.parent.mkdir(parents=True, exist_ok=True)
                remove_stale_building(target)
                building.mkdir()
                (building / BUILDING_SENTINEL).touch()
            except OSError as exc:  # named by the user's folder, not by the hidden one built beside it
                raise DvrkDartError(f"{target}: the output folder cannot be made there ({exc.strerror or exc})") from None
        yield building
        (building / BUILDING_SENTINEL).unlink()
        write_marker(building, kind)
        # two commands finishing into one --out take turns; Ctrl-C waits for the
        # swap (the user's files are in the new folder once carried over)
        with _folder_lock(target.parent), signals_held():
            raise_if_interrupted()
            check_output_folder(target, kind)  # the folder may have changed while this one was built
            if target.is_dir():
                _carry_user_files(target, building)
            swap_in(building, target)
            FOLDERS_WRITTEN.append(target)
    finally:
        with signals_held():  # a Ctrl-C during the removal would leave half of it
            if building.exists():
                shutil.rmtree(building, ignore_errors=True)


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """Ctrl-C and SIGTERM are delivered when the block is over (main thread
    only: elsewhere the process's handlers do not run anyway)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


@contextlib.contextmanager
def _folder_lock(folder: Path) -> Iterator[None]:
    """An exclusive lock on the folder itself (no lock file left behind)."""
    descriptor = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX)
        yield
    finally:
        os.close(descriptor)


def _carry_user_files(old: Path, new: Path) -> None:
    """Move what the old folder's marker does not vouch for into the new folder,
    at the same relative path; refuse (old folder untouched) where the new one
    wrote a file of the same name."""
    marker = read_marker(old) or Marker("", {})
    user = [relative for relative in _files(old) if not marker.owns(old, relative)
            and not ((old / relative).is_dir() and not (old / relative).is_symlink() and (new / relative).is_dir())]  # an empty folder the new one has too
    clashes = [relative for relative in user if (new / relative).exists() or (new / relative).is_symlink()]
    if clashes:
        raise DvrkDartError(f"--out: {old / clashes[0]} is not what dvrk-dart wrote there (a file of yours, or one changed "
                            "since) and the new output writes that file: move it, then run again")
    for relative in user:
        (new / relative).parent.mkdir(parents=True, exist_ok=True)
        os.replace(old / relative, new / relative)


def swap_in(built: Path, target: Path) -> None:
    """Put the folder `built` at `target`, moving a previous one aside first so
    that there is always a complete folder at `target` or the old one."""
    old = None
    if target.exists():
        os.chmod(built, stat.S_IMODE(target.stat().st_mode))  # the folder keeps its permissions (a read-only folder stays so)
        old = target.with_name(f".{target.name}.old-{uuid.uuid4().hex[:8]}")
        os.replace(target, old)
    try:
        os.replace(built, target)
    except OSError:
        if old is not None:  # the previous folder goes back where it was
            os.replace(old, target)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def check_not_inside(inner: str | os.PathLike, outer: str | os.PathLike, inner_option: str, outer_option: str) -> None:
    """`outer` (an output that is replaced whole) may not contain `inner` (an input)."""
    inner_path, outer_path = Path(inner).resolve(), Path(outer).resolve()
    if inner_path == outer_path or outer_path in inner_path.parents:
        raise DvrkDartError(f"{outer_option}: {outer} contains {inner_option} {inner}: the output would replace its own input")
