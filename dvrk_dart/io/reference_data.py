"""Reference data: the manifest of upstream files, the resolver, and the one
loader of measured runs (upstream CSV: no header, q1..q7, dq1..dq7, tau1..tau7
sampled at 200 Hz unless --rate or the manifest's entry of the file says
otherwise; the velocity column is checked against the rate)."""

from __future__ import annotations

import functools
import hashlib
import os
import tomllib
import urllib.request
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np
import pandas as pd

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.atomic import atomic_path
from dvrk_dart.model.joints import N_JOINTS, column_names
from dvrk_dart.paths import PROJECT_DIR

MANIFEST_FILE = PROJECT_DIR / "reference_data" / "manifest.toml"
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
}
CSV_COLUMNS = column_names("q") + column_names("dq") + column_names("tau")


def reference_run_arm(name: str) -> str:
    """The arm model a reference run was recorded on (its data folder: mtm/... is the MTM's)."""
    return RUNS[name].split("/")[0] if "/" in RUNS[name] else "psm"


@cache
def manifest() -> dict:
    return tomllib.loads(MANIFEST_FILE.read_text())


def sample_rate_hz() -> float:
    """The default rate of a measured run's rows (the reference data's, 200 Hz)."""
    return float(manifest()["sample_rate_hz"])


#: a CSV's velocity column must match the finite differences of its positions
#: at its rate to this fraction (the half-speed run read at 200 Hz: 1.0 off)
RATE_TOLERANCE = 0.1


def rate_of(path: Path) -> tuple[float, str]:
    """(rows per second, where it comes from) of a CSV: --rate, else the
    manifest's entry of that file name, else the reference data's default."""
    from dvrk_dart.io.bags import current_topics

    explicit = current_topics().rate_hz
    if explicit is not None:
        if not (np.isfinite(explicit) and explicit > 0):
            raise DvrkDartError(f"--rate: {explicit!r} is not a positive rate (Hz)")
        return float(explicit), "--rate"
    entry = manifest()["files"].get(Path(path).name, {})
    if "sample_rate_hz" in entry:
        return float(entry["sample_rate_hz"]), f"{MANIFEST_FILE.name} [{Path(path).name}]"
    return sample_rate_hz(), "the default rate"


def check_rate(q: np.ndarray, dq: np.ndarray, rate_hz: float, where: str, source: str) -> None:
    """The velocity column against finite differences of the positions at the
    rate: a mismatch names the rate that fits. Each joint's least-squares
    scale is biased low by its velocity column's noise (a noisy wrist joint:
    7 % low), so the clock is the median of the upper half of the joints'
    scales: the cleanest joints, and still no single odd column."""
    differences = np.gradient(q, 1.0 / rate_hz, axis=0)
    moving = (np.sum(differences**2, axis=0) > 0) & (np.sum(dq**2, axis=0) > 0)
    if not moving.any():
        return  # a still arm says nothing of its rate
    scales = np.sort(np.sum(differences * dq, axis=0)[moving] / np.sum(dq**2, axis=0)[moving])
    scale = float(np.median(scales[len(scales) // 2:]))
    if not scale > 0:
        raise DvrkDartError(f"{where}: the velocity column runs against the positions' finite differences (rows in reverse order, "
                            "or the velocities' sign flipped)")
    if abs(scale - 1.0) > RATE_TOLERANCE:
        fits = rate_hz / scale
        raise DvrkDartError(f"{where}: at {rate_hz:g} Hz ({source}) the positions' finite differences are {scale:.2f} times the velocity "
                            f"column; the rate that fits is {fits:.4g} Hz (--rate {fits:.4g})")


#: a row stands out as a glitch when its disagreement is this many times the
#: 99th percentile of the column's (the reference runs' largest: 3.7 times)
GLITCH_RATIO = 30.0


def _outlier_row(x: np.ndarray) -> tuple[int, int] | None:
    """(row, column) of the largest value of |x| if it exceeds GLITCH_RATIO times its column's 99th percentile."""
    scale = np.maximum(np.percentile(x, 99, axis=0), np.finfo(float).tiny)
    rows = np.argmax(x, axis=0)  # each column's worst row, then the column that stands out most
    with np.errstate(over="ignore"):
        ratio = x[rows, np.arange(x.shape[1])] / scale
    column = int(np.argmax(ratio))
    return (int(rows[column]), column) if ratio[column] > GLITCH_RATIO else None


def check_glitches(values: np.ndarray, rate_hz: float, where: str) -> None:
    """One bad row (a glitched value, rows out of order) refused with its row
    number: a velocity that disagrees with the positions' finite differences,
    or an effort that stands out of its neighbours, far more than anywhere else."""
    q, dq, tau = values[:, :N_JOINTS], values[:, N_JOINTS : 2 * N_JOINTS], values[:, 2 * N_JOINTS :]
    velocity = _outlier_row(np.abs(dq - np.gradient(q, 1.0 / rate_hz, axis=0)))
    if velocity is not None:
        row, j = velocity
        raise DvrkDartError(f"{where}: row {row + 1}: the velocity column {CSV_COLUMNS[N_JOINTS + j]} ({dq[row, j]:.6g}) and the finite "
                            f"differences of {CSV_COLUMNS[j]} disagree {GLITCH_RATIO:g} times more than on 99 % of the rows "
                            "(a glitched value, or rows out of order)")
    effort = _outlier_row(np.abs(tau[1:-1] - 0.5 * (tau[:-2] + tau[2:])))
    if effort is not None:
        row, j = effort
        raise DvrkDartError(f"{where}: row {row + 2}, column {CSV_COLUMNS[2 * N_JOINTS + j]}: {tau[row + 1, j]:.6g} stands out of its "
                            f"neighbouring rows {GLITCH_RATIO:g} times more than on 99 % of the rows (a glitched value)")


def input_record(path: str | Path) -> dict:
    """What an output records of a measured-run file it used: path, sha256 and
    the options that selected its data (a bag's topics, a CSV's rate)."""
    from dvrk_dart.io.bags import current_topics, is_bag

    path = Path(path)
    entry = {"path": str(path), "sha256": sha256_of(path)}
    if is_bag(path):
        topics = current_topics()
        entry["bag_topics"] = {"arm": topics.arm, "topic": topics.joint_topic, "jaw_topic": topics.jaw, "rate_hz": topics.rate}
    else:
        entry["rate_hz"], entry["rate_from"] = rate_of(path)
    return entry


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


def _checked(path: Path, name: str) -> Path:
    expected = manifest()["files"][name]["sha256"]
    actual = sha256_of(path)
    if actual != expected:
        raise DvrkDartError(f"{path}: sha256 {actual[:12]}... does not match the manifest ({expected[:12]}...)")
    return path


def cache_dir() -> Path:
    return Path(os.environ.get(ENV_CACHE_DIR, Path.home() / ".cache" / "dvrk_dart")) / manifest()["commit"][:12]


def _download(name: str) -> Path:
    m = manifest()
    entry = m["files"][name]
    template = os.environ.get(ENV_URL_TEMPLATE, m["url_template"])
    url = template.format(repository=m["repository"], commit=m["commit"], path=entry["path"])
    target = cache_dir() / name
    try:
        with atomic_path(target) as tmp:
            with urllib.request.urlopen(url, timeout=60) as response:
                tmp.write_bytes(response.read())
            _checked(tmp, name)
    except DvrkDartError:
        raise DvrkDartError(f"{url}: downloaded file fails its sha256 check") from None
    except OSError as exc:
        raise DvrkDartError(f"{name}: not found locally and download from {url} failed ({exc})") from None
    return target


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
    candidates = []
    if os.environ.get(ENV_DATA_DIR):
        folder = Path(os.environ[ENV_DATA_DIR])
        if not folder.is_dir():  # a setting the user made must not be silently ignored
            raise DvrkDartError(f"{ENV_DATA_DIR}={folder}: not a folder")
        candidates.append(folder)
    paths = [folder / name for folder in candidates]
    paths += [SHARED_ROOT / manifest()["files"][name].get("local", f"wpi/{name}"), cache_dir() / name]
    for path in paths:
        if path.is_file():
            return _checked(path, name)
    return _download(name)


def resolve_run(name_or_path: str | Path) -> Path:
    """A measured run by shorthand ('two'), manifest name or path (a CSV or a
    ROS bag: a rosbag2 folder, an .mcap/.db3 file or a ROS 1 .bag)."""
    from dvrk_dart.io.bags import is_bag

    text = str(name_or_path)
    if text in RUNS:
        return resolve(RUNS[text])
    if text in manifest()["files"]:
        return resolve(text)
    if is_bag(text):
        return Path(text)
    if Path(text).is_dir():
        raise DvrkDartError(f"{text}: a folder without metadata.yaml, not a rosbag2 bag")
    return resolve(text, explicit=text)


#: two recordings whose positions agree to this on a whole window are one
#: recording (rad, m): two sessions differ by the encoders' noise, 1e-4 and
#: more; a copy with noise added below a tenth of that is still the same recording
SAME_RECORDING_TOLERANCE = 1e-5
SAME_RECORDING_WINDOW = 50


def distinct_inputs(roles: list[tuple[str, str | Path]]) -> dict[str, dict]:
    """(option, run) pairs -> {run: {"role", "path", "sha256"}}; the same
    recording in two roles, or twice in one, is refused in one line naming
    both: the same path or content, or the same positions however the file was
    written (line endings, digits, a trimmed copy)."""
    seen: list[tuple[str, str, str, np.ndarray]] = []
    inputs = {}
    for option, spec in roles:
        path = Path(resolve_run(spec))
        q = load_run(path).q
        record = input_record(path)
        digest = record["sha256"]
        for other_option, other, other_digest, other_q in seen:
            if digest == other_digest or same_recording(q, other_q):
                raise DvrkDartError(f"{option} {spec}: the same recording as {other_option} {other} "
                                    f"({'same content' if digest == other_digest else 'same positions'}): "
                                    "each role needs its own recording")
        seen.append((option, str(spec), digest, q))
        inputs[str(spec)] = {"role": option, **record}
    return inputs


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


@dataclass(frozen=True)
class MeasuredRun:
    """A measured run: named, typed columns t, q1..q7, dq1..dq7, tau1..tau7."""

    path: Path
    data: pd.DataFrame

    @property
    def name(self) -> str:
        return self.path.stem

    @property
    def t(self) -> np.ndarray:
        return self.data["t"].to_numpy()

    @property
    def rate_hz(self) -> float:
        """Rows per second (checked against the velocity column when loaded)."""
        return float(1.0 / (self.data["t"].iat[1] - self.data["t"].iat[0]))

    @property
    def q(self) -> np.ndarray:
        return self.data[column_names("q")].to_numpy()

    @property
    def dq(self) -> np.ndarray:
        return self.data[column_names("dq")].to_numpy()

    @property
    def tau(self) -> np.ndarray:
        return self.data[column_names("tau")].to_numpy()

    def __len__(self) -> int:
        return len(self.data)


def check_joint_ranges(q: np.ndarray, where: str | Path) -> None:
    """Positions within the model's joint ranges (the simulator's own limits)."""
    lower, upper = joint_ranges()
    outside = (q < lower) | (q > upper)
    if outside.any():
        row, j = np.argwhere(outside)[0]
        raise DvrkDartError(
            f"{where}: row {row + 1}, column {CSV_COLUMNS[j]}: {float(q[row, j])!r} outside the joint range "
            f"[{float(lower[j])!r}, {float(upper[j])!r}]" + _other_arm_fitting(q)
        )


def _other_arm_fitting(q: np.ndarray) -> str:
    """' (... --arm-model X)' when every row lies in the joint ranges of another arm model."""
    from dvrk_dart.model.description import current_model_file
    from dvrk_dart.paths import MODELS_DIR

    for folder in sorted(p for p in MODELS_DIR.iterdir() if (p / f"{p.name}.toml").is_file()):
        model_file = folder / f"{folder.name}.toml"
        if model_file.resolve() == current_model_file().resolve():
            continue
        lower, upper = _joint_ranges_of(model_file)
        if np.all((q >= lower) & (q <= upper)):
            return f" (every row fits the {folder.name} arm model's ranges: --arm-model {folder.name})"
    return ""


def joint_ranges() -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) joint ranges of the current arm's model description (rad, m)."""
    from dvrk_dart.model.description import current_model_file

    return _joint_ranges_of(current_model_file())


@functools.cache
def _joint_ranges_of(model_file: Path) -> tuple[np.ndarray, np.ndarray]:
    from dvrk_dart.model.description import load_model

    model = load_model(model_file)
    return model.joint_lower, model.joint_upper


def _numbers_or_error(path: Path) -> np.ndarray:
    """Read the CSV as text to name the first cell that is not a number."""
    try:
        raw = pd.read_csv(path, header=None, dtype=str, skip_blank_lines=True, index_col=False)
    except pd.errors.EmptyDataError:
        raise DvrkDartError(f"{path}: file is empty") from None
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise DvrkDartError(f"{path}: not a CSV file ({str(exc).splitlines()[0]})") from None
    if raw.shape[1] != len(CSV_COLUMNS):
        raise DvrkDartError(f"{path}: {raw.shape[1]} columns, expected {len(CSV_COLUMNS)} (q1..q7, dq1..dq7, tau1..tau7)")
    numeric = raw.apply(pd.to_numeric, errors="coerce")
    bad = numeric.isna() & raw.notna()
    if bad.to_numpy().any():
        row, col = np.argwhere(bad.to_numpy())[0]
        raise DvrkDartError(f"{path}: row {row + 1}, column {CSV_COLUMNS[col]}: '{raw.iat[row, col]}' is not a number")
    return numeric.to_numpy(dtype=float)


def load_run(path: Path | str) -> MeasuredRun:
    """Load a measured run (the upstream CSV format, or a ROS bag read with the
    command's topics: io/bags.py), with one-line errors."""
    from dvrk_dart.io.bags import is_bag, load_bag_run

    path = Path(path)
    if is_bag(path):
        return load_bag_run(path)
    if not path.is_file():
        raise DvrkDartError(f"{path}: file not found")
    if not os.access(path, os.R_OK):
        raise DvrkDartError(f"{path}: not readable (permission denied)")
    try:
        values = pd.read_csv(path, header=None, dtype=float, skip_blank_lines=True, index_col=False).to_numpy()
    except (ValueError, pd.errors.ParserError, UnicodeDecodeError):  # a well-formed file reads as numbers at once
        values = _numbers_or_error(path)
    if values.shape[1] != len(CSV_COLUMNS):
        raise DvrkDartError(f"{path}: {values.shape[1]} columns, expected {len(CSV_COLUMNS)} (q1..q7, dq1..dq7, tau1..tau7)")
    if not np.all(np.isfinite(values)):
        row, col = np.argwhere(~np.isfinite(values))[0]
        raise DvrkDartError(f"{path}: row {row + 1}, column {CSV_COLUMNS[col]}: missing, NaN or infinite value")
    from dvrk_dart.io.signal import (
        MIN_ROWS,  # the processing's own need (signal imports this module)
    )

    if len(values) < MIN_ROWS:
        raise DvrkDartError(f"{path}: {len(values)} rows, at least {MIN_ROWS} needed (the processing trims {MIN_ROWS // 2 - 1} from each end)")
    check_joint_ranges(values[:, :N_JOINTS], path)
    rate, source = rate_of(path)
    check_glitches(values, rate, str(path))  # first: a jump in the positions also skews the rate's estimate
    check_rate(values[:, :N_JOINTS], values[:, N_JOINTS : 2 * N_JOINTS], rate, str(path), source)
    data = pd.DataFrame(values, columns=CSV_COLUMNS)
    data.insert(0, "t", np.arange(len(data)) / rate)
    assert data.shape[1] == 1 + 3 * N_JOINTS
    return MeasuredRun(path=path, data=data)
