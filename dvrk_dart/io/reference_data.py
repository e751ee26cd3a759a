"""Reference data: the manifest of upstream files, the resolver, and the one
loader of measured runs (upstream CSV: no header, q1..q7, dq1..dq7, tau1..tau7
sampled at 200 Hz unless --rate or the manifest's entry of the file says
otherwise; the velocity column is checked against the rate)."""

from __future__ import annotations

import functools
import hashlib
import http.client
import os
import time
import urllib.request
from pathlib import Path

import numpy as np
import pandas as pd

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.atomic import atomic_path
from dvrk_dart.model.joints import N_JOINTS
from dvrk_dart.io.bags import BagTopics, is_bag, load_bag_run
from dvrk_dart.io.csv_run import CsvValues, joints_with_efforts, read_csv_run, say_once, still_position_notes
from dvrk_dart.io.measured_run import (  # noqa: F401  (re-exported: the readers' names)
    CSV_COLUMNS,
    MANIFEST_FILE,
    MeasuredRun,
    check_glitches,
    check_joint_ranges,
    TIME_COLUMN_SOURCE,
    check_rate,
    check_velocity_columns,
    manifest,
    sample_rate_hz,
)
from dvrk_dart.io.provenance import file_record, sha256_of  # noqa: F401  (sha256_of re-exported)
from dvrk_dart.io.signal import CUT_SAMPLES, MIN_ROWS, forget_analyses
from dvrk_dart.io.period import spanning_columns
from dvrk_dart.model.description import PsmModel
from dvrk_dart.paths import PROJECT_DIR

SHARED_ROOT = PROJECT_DIR.parent / "shared" / "reference_data"
ENV_DATA_DIR = "DVRK_REFERENCE_DATA"
ENV_CACHE_DIR = "DVRK_DART_CACHE"
ENV_URL_TEMPLATE = "DVRK_REFERENCE_URL"  # override of the download URL (tests, mirrors)

#: the shorthand names of the reference runs
RUNS = {
    "one": "one_results.csv",
    "two": "two_results.csv",
    "one-no-weight": "one_no_weight_results.csv",
    "one-105g": "one_105_grams_parallel_results.csv",
    "one-105g-half": "one_105_grams_parallel_half_speed_results.csv",
    "one-105g-insertion": "one_105_grams_insertion_results.csv",
    "mtm-one": "mtm/one_results.csv",
    "mtm-two": "mtm/two_results.csv",
    "2018-test1": "2018/psm1_fourier_test1.csv",
    "2018-test2": "2018/psm1_fourier_test2.csv",
}
def manifest_name(path: Path) -> str | None:
    """The manifest's name of a file, by content (wherever it is, whatever it is called); None for a file it does not list."""
    digest = sha256_of(path)
    return next((name for name, entry in manifest()["files"].items() if entry.get("sha256") == digest), None)


def recording_facts(path: Path) -> tuple[float, str] | None:
    """(the weight a reference recording carries: the manifest's attached_mass_kg, 0 where it gives none; the
    repository it comes from), by content; None for a file the manifest does not list."""
    name = manifest_name(path)
    return None if name is None else (float(manifest()["files"][name].get("attached_mass_kg", 0.0)), _source(name)[0])


def attached_mass_kg(path: Path) -> float | None:
    """The weight a reference recording carries (`recording_facts`); None for a file the manifest does not list."""
    facts = recording_facts(path)
    return None if facts is None else facts[0]


def reference_run_arm(name: str) -> str:
    """The arm model a reference run was recorded on (its data folder: mtm/... is the MTM's)."""
    folder = RUNS[name].split("/")[0] if "/" in RUNS[name] else "psm"
    return folder if folder == "mtm" else "psm"


def rate_of(path: Path, time_column_hz: float | None = None, explicit: float | None = None) -> tuple[float, str]:
    """(rows per second, where it comes from) of a CSV: its time column's, else --rate (`explicit`), else the
    manifest's entry of that file name, else the reference data's default. --rate is the rate of the files
    whose rate is not known: a command may mix them with files that have a time column, or with the
    reference data's runs (their content the manifest's), which keep their own rate (a note says so where
    --rate differs by more than 1 %)."""
    if explicit is not None and not (np.isfinite(explicit) and explicit > 0):
        raise DvrkDartError(f"--rate: {explicit!r} is not a positive rate (Hz)")
    if time_column_hz is not None:
        _say_rate_not_used(explicit, time_column_hz, f"{path} keeps its own")
        return time_column_hz, TIME_COLUMN_SOURCE
    files = manifest()["files"]
    if explicit is not None:  # a reference run, wherever it is and whatever its name, keeps its recorded rate
        name = manifest_name(path)
        if name is None:
            return float(explicit), "--rate"
    else:
        name = Path(path).name
    entry = files.get(name, {})
    known = float(entry.get("sample_rate_hz", sample_rate_hz()))
    if explicit is not None:
        _say_rate_not_used(explicit, known, f"{path} is the reference data's {name}, recorded at")
    return known, f"{MANIFEST_FILE.name} [{name}]" if "sample_rate_hz" in entry else "the default rate"


def _say_rate_not_used(explicit: float | None, rate_hz: float, whose: str) -> None:
    if explicit is not None and abs(explicit / rate_hz - 1.0) > 0.01:
        say_once([f"--rate {explicit:g} is for the files whose rate is not known: {whose} {rate_hz:.6g} Hz"])


def input_record(path: str | Path, model: PsmModel, topics: BagTopics = BagTopics()) -> dict:
    """What an output records of a measured-run file of `model`'s arm it used:
    `file_record` and the options that selected its data (a bag's topics, a CSV's rate)."""
    path = Path(path)
    entry = file_record(path)
    if is_bag(path):
        entry["bag_topics"] = topics.record(model.dvrk_topics)
    else:
        entry["rate_hz"], entry["rate_from"] = rate_of(path, _time_column_rate(path, model), topics.rate_hz)
    return entry


def _time_column_rate(path: Path, model: PsmModel) -> float | None:
    return _read_csv(path, model).rate_hz


def _read_csv(path: Path, model: PsmModel) -> CsvValues:
    """A measured-run CSV parsed once per content: a command loads a run, records it in its outputs and may
    load it again (a replay chooses its processing first). Keyed by the bytes' digest, not the file's time
    (a file rewritten within a clock tick); its values are read-only."""
    try:
        digest = hashlib.blake2b(path.read_bytes(), digest_size=16).hexdigest()
    except OSError:  # read_csv_run says what is wrong with the path
        return read_csv_run(path, model.motor_map, model.dvrk_topics.joint_names)
    return _read_csv_version(str(path), digest, model.motor_map, tuple(model.dvrk_topics.joint_names))


@functools.lru_cache(maxsize=32)
def _read_csv_version(path: str, digest: str, motor_map, joint_names: tuple) -> CsvValues:
    read = read_csv_run(Path(path), motor_map, joint_names)
    read.values.setflags(write=False)
    return read


def forget_read_runs() -> None:
    """Drop what this process keeps of the runs it read (their parse, their periodic analysis): a benchmark times
    each replay as a process of its own makes it."""
    _read_csv_version.cache_clear()
    forget_analyses()


def _checked(path: Path, name: str, cached: bool = False) -> Path:
    expected = manifest()["files"][name]["sha256"]
    actual = sha256_of(path)
    if actual != expected:
        again = ": a download's copy, delete it to download it again" if cached else ""
        raise DvrkDartError(f"{path}: sha256 {actual[:12]}... does not match the manifest ({expected[:12]}...){again}")
    return path


def _source(name: str | None) -> tuple[str, str]:
    """(repository, commit) a manifest file comes from: its entry's, else the manifest's."""
    m = manifest()
    entry = m["files"].get(name, {}) if name else {}
    return entry.get("repository", m["repository"]), entry.get("commit", m["commit"])


def cache_dir(name: str | None = None) -> Path:
    """Where downloads of the pinned commit (of `name`'s repository) are kept (DVRK_DART_CACHE, set and not empty)."""
    return Path(os.environ.get(ENV_CACHE_DIR) or Path.home() / ".cache" / "dvrk_dart") / _source(name)[1][:12]


#: a download that has not arrived whole after this long has failed (a server sending a byte at a time never times out a read)
DOWNLOAD_DEADLINE_S = 300.0


def _download(name: str) -> Path:
    m = manifest()
    entry = m["files"][name]
    template = os.environ.get(ENV_URL_TEMPLATE) or m["url_template"]
    repository, commit = _source(name)
    try:
        url = template.format(repository=repository, commit=commit, path=entry["path"])
    except (KeyError, IndexError, ValueError) as exc:
        raise DvrkDartError(f"{ENV_URL_TEMPLATE}={template}: not a URL template with {{repository}}, {{commit}} and {{path}} ({exc!r})") from None
    target = cache_dir(name) / name
    if target.is_symlink():  # the user's, not a download: never replaced
        raise DvrkDartError(f"{target}: a link in the download cache, which holds only downloads: remove it, or point it to the file")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DvrkDartError(f"{target.parent}: the download cache cannot be made there ({exc.strerror or exc}; {ENV_CACHE_DIR} sets it)") from None
    try:
        with atomic_path(target) as tmp:
            tmp.write_bytes(_fetch(url))
            _checked(tmp, name)
    except DvrkDartError:
        raise DvrkDartError(f"{url}: downloaded file fails its sha256 check") from None
    except (OSError, ValueError, http.client.HTTPException) as exc:  # ValueError: a URL of no known scheme
        raise DvrkDartError(f"{name}: not found in {_searched()} and download from {url} failed ({exc!r})") from None
    return target


def _fetch(url: str) -> bytes:
    """The bytes at `url`, whole within DOWNLOAD_DEADLINE_S."""
    start, chunks = time.monotonic(), []
    with urllib.request.urlopen(url, timeout=60) as response:
        read = getattr(response, "read1", response.read)  # what has arrived, so that the deadline is checked
        while chunk := read(1 << 16):
            chunks.append(chunk)
            if time.monotonic() - start > DOWNLOAD_DEADLINE_S:
                raise TimeoutError(f"not whole after {DOWNLOAD_DEADLINE_S:g} s")
    return b"".join(chunks)


def _searched() -> str:
    """Where a reference file was looked for before a download, in words."""
    places = [f"{ENV_DATA_DIR}={os.environ[ENV_DATA_DIR]}"] if os.environ.get(ENV_DATA_DIR) else []
    return ", ".join([*places, str(SHARED_ROOT), "the download cache"])


def resolve(name: str, explicit: Path | str | None = None) -> Path:
    """Locate a reference file by manifest name (explicit path wins, unchecked)."""
    if explicit is not None:
        path = Path(explicit)
        if path.is_dir():
            raise DvrkDartError(f"{path}: a folder, where the file {name} was expected")
        if not path.is_file():
            raise DvrkDartError(f"{path}: file not found")
        return path
    if name not in manifest()["files"]:
        raise DvrkDartError(f"unknown reference file '{name}' (known: {', '.join(manifest()['files'])})")
    local = manifest()["files"][name].get("local", f"wpi/{name}")  # where ../shared/reference_data keeps it
    own = []
    if os.environ.get(ENV_DATA_DIR):
        folder = Path(os.environ[ENV_DATA_DIR])
        if not folder.is_dir():  # a setting the user made must not be silently ignored
            raise DvrkDartError(f"{ENV_DATA_DIR}={folder}: not a folder")
        own = [folder / name, folder / local]  # the manifest's names, or a copy of ../shared/reference_data
    for path in [*own, SHARED_ROOT / local, cache_dir(name) / name]:
        if path.is_file():
            if own and path not in own:
                say_once([f"{ENV_DATA_DIR}={folder} holds neither {name} nor {local}: read {path}"])
            return _checked(path, name, cached=path == cache_dir(name) / name)
    return _download(name)


def resolve_run(name_or_path: str | Path) -> Path:
    """A measured run by shorthand ('two'), manifest name or path (a CSV or a
    ROS bag: a rosbag2 folder, an .mcap/.db3 file or a ROS 1 .bag)."""
    text = str(name_or_path)
    here = Path(text).exists() or Path(text).is_symlink()
    if text in RUNS:
        if here:
            raise DvrkDartError(f"{text}: both the reference run '{text}' and a file here: give ./{text} for the file")
        return resolve(RUNS[text])
    if text in manifest()["files"] and not here:  # a file of that name where the user points wins
        path = resolve(text)
        say_once([f"{text}: no such file here; read the reference data's {path}"])
        return path
    if is_bag(text):
        return Path(text)
    if Path(text).is_dir():
        raise DvrkDartError(f"{text}: a folder without metadata.yaml, not a rosbag2 bag")
    return resolve(text, explicit=text)


def run_label(name_or_path: str | Path) -> str:
    """How outputs name a run: its reference name as given ('two'), else its
    file's or bag's stem ('two_results' for two_results.csv)."""
    text = str(name_or_path)
    return text if text in RUNS else Path(text).stem


def distinct_labels(specs) -> dict[str, str]:
    """run_label of each run (name or path, by its text), with as many of its
    folders as tell two files of one name apart (a/run.csv, b/run.csv: a/run, b/run)."""
    texts = list(dict.fromkeys(str(s) for s in specs))
    parts = {t: (t,) if t in RUNS else (*Path(t).parent.parts, Path(t).stem) for t in texts}
    depth = dict.fromkeys(texts, 1)
    while True:  # past every folder, the text itself (a/run.csv beside a bag a/run)
        labels = {t: "/".join(parts[t][-depth[t]:]) if depth[t] <= len(parts[t]) else t for t in texts}
        clashes = [t for t in texts if list(labels.values()).count(labels[t]) > 1 and depth[t] <= len(parts[t])]
        if not clashes:
            return labels
        for t in clashes:
            depth[t] += 1


#: two recordings whose positions agree to this on a whole window are one
#: recording (rad, m): two sessions differ by the encoders' noise, 1e-4 and
#: more; a copy with noise added below a tenth of that is still the same recording
SAME_RECORDING_TOLERANCE = 1e-5
SAME_RECORDING_WINDOW = 50


def distinct_inputs(roles: list[tuple[str, str | Path]], model: PsmModel, topics: BagTopics = BagTopics()) -> dict[str, dict]:
    """(option, run) pairs -> {run: {"role", "path", "sha256"}}; the same
    recording in two roles, or twice in one, is refused in one line naming
    both: the same path or content, or the same positions however the file was
    written (line endings, digits, a trimmed copy, some of its columns)."""
    seen: list[tuple[str, str, str, np.ndarray, float, np.ndarray]] = []
    inputs = {}
    for option, spec in roles:
        path = Path(resolve_run(spec))
        run = load_run(path, model, topics)
        record = input_record(path, model, topics)
        digest = record["sha256"]
        for other_option, other, other_digest, other_q, other_rate, other_recorded in seen:
            # a file of some of a recording's columns is that recording too (compared on the moving ones: still joints agree anywhere)
            common = run.measured_mask & other_recorded & spanning_columns(run.q) & spanning_columns(other_q)
            if digest == other_digest or (common.any() and same_recording_at_rates(run.q[:, common], run.rate_hz, other_q[:, common], other_rate)):
                raise DvrkDartError(f"{option} {spec}: the same recording as {other_option} {other} "
                                    f"({'same content' if digest == other_digest else 'same positions'}): "
                                    "each role needs its own recording")
        seen.append((option, str(spec), digest, run.q, run.rate_hz, run.measured_mask))
        inputs[str(spec)] = {"role": option, **record}
    return inputs


def same_recording_at_rates(a: np.ndarray, rate_a: float, b: np.ndarray, rate_b: float) -> bool:
    """`same_recording`, and a copy kept every k-th row (read at a k times
    lower rate, or given as such by a manifest name) is the same recording too."""
    if same_recording(a, b):
        return True
    (slow, slow_rate), (fast, fast_rate) = sorted(((a, rate_a), (b, rate_b)), key=lambda x: x[1])
    k = round(fast_rate / slow_rate)
    if k < 2 or abs(fast_rate / slow_rate - k) > 1e-6 * k:
        k = 2  # a decimated copy read at the rate of its name: try every other row too
    return any(same_recording(slow, fast[offset::k]) or same_recording(fast, slow[offset::k]) for offset in range(k))


def same_recording(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether the positions `a` hold a window of `b`'s, or `b` of `a`'s, sample
    for sample (a copy, re-saved or trimmed: no two sessions agree that well)."""
    def window_of(short: np.ndarray, long: np.ndarray) -> bool:
        middle = max(0, len(short) // 2 - SAME_RECORDING_WINDOW // 2)  # moving there; a still start is alike in any two sessions
        head = short[middle:middle + SAME_RECORDING_WINDOW]
        starts = np.flatnonzero(np.all(np.abs(long - head[0]) <= SAME_RECORDING_TOLERANCE, axis=1))
        return any(len(long) - k >= len(head)
                   and np.all(np.abs(long[k:k + len(head)] - head) <= SAME_RECORDING_TOLERANCE) for k in starts)

    return window_of(a, b) or window_of(b, a)


def load_run(path: Path | str, model: PsmModel, topics: BagTopics = BagTopics()) -> MeasuredRun:
    """Load a measured run of `model`'s arm (a CSV in any layout of io/csv_run.py,
    or a ROS bag read with the command's `topics`: io/bags.py), with one-line errors."""
    path = Path(path)
    if is_bag(path):
        run = load_bag_run(path, model, topics)
        where = f"{path} (on its {run.rate_hz:g} Hz grid)"
        values = np.hstack([run.q, run.dq, run.tau])
        # an effort glitch, as a CSV's (one of 1000 was fitted as data); not the velocities: a bag's are the arm's own,
        # its messages in order by their stamps, and a wrist's transient in the tool's own exports stood 44 times out
        check_glitches(values, run.rate_hz, where, velocities=False)
        say_once(check_velocity_columns(run.q, run.dq, run.rate_hz, where) + still_position_notes(values, run.measured, path))
        return run
    read = _read_csv(path, model)
    values = read.values
    if len(values) < MIN_ROWS:
        raise DvrkDartError(f"{path}: {len(values)} rows, at least {MIN_ROWS} needed (the processing trims {CUT_SAMPLES} from each end)")
    check_joint_ranges(values[:, :N_JOINTS], path, model)
    rate, source = rate_of(path, read.rate_hz, topics.rate_hz)
    check_glitches(values, rate, str(path))  # first: a jump in the positions also skews the rate's estimate
    check_rate(values[:, :N_JOINTS], values[:, N_JOINTS : 2 * N_JOINTS], rate, str(path), source)
    velocity_notes = check_velocity_columns(values[:, :N_JOINTS], values[:, N_JOINTS : 2 * N_JOINTS], rate, str(path))
    measured, effort_notes = joints_with_efforts(read, path)
    say_once(velocity_notes + effort_notes + still_position_notes(values, measured, path))  # last: notes only for a file that loads
    data = pd.DataFrame(values, columns=CSV_COLUMNS, copy=True)  # the parse is shared (read-only): the run owns its copy
    data.insert(0, "t", np.arange(len(data)) / rate)
    return MeasuredRun(path=path, data=data, model=model, measured=measured)
