"""Measured runs from CSV files in the layouts users have (io/ leaf reader):

- no header, 21 columns: q1..q7, dq1..dq7, tau1..tau7 (the `wpi/` identification logs);
- no header, 9 columns: q1..q3, dq1..dq3, tau1..tau3 (the dVRK Python API's
  3-joint logs, `wpi-2018/`: joints 4..7 not recorded);
- a header row naming its columns: `t` (or `time`, s) optional; `q1..q7`,
  `dq1..dq7`, `tau1..tau7` in the model's coordinates, or
  `position|velocity|effort` + `.`/`_`/`/` + the dVRK's joint name
  (`position.outer_yaw`, the arm's model card [dvrk_topics]) in the dVRK's;
  any subset of joints, each with its position, velocity and effort.

A joint that is not recorded is *not measured* (`MeasuredRun.measured`): its
columns hold zeros (the arm held at zero) and no figure, fit or cutoff uses it.
So is one whose effort column holds one value (zeros padding a layout, a
logger that did not read it: `joints_with_efforts`); its positions are kept.
A time column gives the file its own rate (rows must be evenly spaced)."""

from __future__ import annotations

import math
import os
import re
import sys
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS

FIELDS = ("q", "dq", "tau")
#: the header's words for the dVRK's JointState fields
DVRK_FIELDS = {"position": "q", "velocity": "dq", "effort": "tau"}
TIME_NAMES = ("t", "time", "time_s")
#: headerless layouts: column count -> the joints recorded (each with q, dq, tau)
HEADERLESS_JOINTS = {3 * N_JOINTS: JOINT_NAMES, 9: JOINT_NAMES[:3]}
#: rows of a time column may be this far from even spacing (a fraction of the step)
TIME_JITTER = 0.05
#: the notes this process has printed (each once)
_NOTES_SAID: set[str] = set()
#: where notes go instead of stderr (`notes_kept`), innermost last
_NOTE_SINKS: list[list[str]] = []
#: fewer rows are no recording (the processing's own minimum is checked by the loader)
MIN_TIME_ROWS = 3


@dataclass(frozen=True)
class CsvLayout:
    """Where each quantity is in the file: `columns[(field, joint)]` -> column index."""

    columns: dict
    time_column: int | None
    joints: tuple[str, ...]  # the recorded joints, in the model's order
    dvrk_names: bool  # the header names the dVRK's joints (wrist values need the coupling)

    def describe(self) -> str:
        return f"{' '.join(self.joints)} recorded" + (", time column" if self.time_column is not None else "")


def _read_text(path: Path) -> pd.DataFrame:
    if not path.is_file():
        raise DvrkDartError(f"{path}: file not found")
    if not os.access(path, os.R_OK):
        raise DvrkDartError(f"{path}: not readable (permission denied)")
    try:
        # only an empty cell is missing: a written "nan" stays text, so a row of them is named as bad, never dropped as blank
        raw = pd.read_csv(path, header=None, dtype=str, skip_blank_lines=True, index_col=False, comment="#",
                          keep_default_na=False, na_values=[""])
    except pd.errors.EmptyDataError:
        raise DvrkDartError(f"{path}: file is empty") from None
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        more = " (a trailing comma, or a row with more cells than the first?)" if "Expected" in str(exc) else ""
        if "Expected" in str(exc):
            more = _semicolon_hint(path) or more
        raise DvrkDartError(f"{path}: not a CSV file ({str(exc).splitlines()[0]}){more}") from None
    first = str(raw.iloc[0, 0]) if raw.shape[1] == 1 and len(raw) else ""
    for separator, words, fix in ((None, "spaces or tabs", "numpy.savetxt(..., delimiter=',')"), (";", "semicolons", "sep=','")):
        if len(first.split(separator)) > 1 and all(is_number(cell) for cell in first.split(separator)):  # numpy.savetxt's default
            raise DvrkDartError(f"{path}: the columns are separated by {words}; the layouts are comma-separated ({fix})")
    return raw.dropna(how="all").reset_index(drop=True)  # a spreadsheet's rows of empty cells (",,,,"), as blank lines


def _semicolon_hint(path: Path) -> str:
    """Where the first line has semicolons, the likely reason the commas do not split it as expected."""
    with open(path, errors="replace") as text:
        first = next((line for line in text if line.strip() and not line.lstrip().startswith("#")), "")
    if ";" not in first:
        return ""
    return " (semicolons between the columns and decimal commas? the layouts are comma-separated, with decimal points)"


#: cells that mean a missing value (R's, databases'), besides what float() reads as not finite ("nan", "inf")
MISSING_TEXTS = ("na", "n/a", "null", "none")


def is_missing(text) -> bool:
    """A cell that stands for a missing value: empty, a missing spelling, or a number that is not finite."""
    if not isinstance(text, str):
        return True  # an empty cell
    cell = text.strip().lower()
    return cell in MISSING_TEXTS or (is_number(cell) and not math.isfinite(float(cell)))


def is_number(text) -> bool:
    try:
        float(text)
        return True
    except (TypeError, ValueError):
        return False


def _has_header(raw: pd.DataFrame) -> bool:
    """A first row of names: no cell of it is a number (a data row with one bad
    cell is a data row, and its error names the cell)."""
    first = [cell for cell in raw.iloc[0] if isinstance(cell, str) and not is_missing(cell)]
    return bool(first) and not any(is_number(cell) for cell in first) and any(re.search(r"[A-Za-z]", c) for c in first)


def _header_key(name: str, dvrk_joints: tuple[str, ...]) -> tuple[str, str, bool] | None:
    """(field, joint, is a dVRK joint name) of a header cell, or None."""
    text = name.strip().lower()
    match = re.fullmatch(r"(q|dq|tau)([1-7])", text)
    if match:
        return match.group(1), f"q{match.group(2)}", False
    match = re.fullmatch(r"(position|velocity|effort)[._/](.+)", text)
    if match and match.group(2) in dvrk_joints:
        return DVRK_FIELDS[match.group(1)], JOINT_NAMES[dvrk_joints.index(match.group(2))], True
    return None


def layout_from_header(header: list[str], path: Path, dvrk_joints: tuple[str, ...]) -> CsvLayout:
    """The layout a header row names; one line naming a cell it cannot place."""
    columns, time_column, kinds = {}, None, set()
    for index, cell in enumerate(header):
        if not isinstance(cell, str) or not cell.strip():
            why = "an index column? (pandas: to_csv(..., index=False))" if index == 0 else "a trailing comma?"
            raise DvrkDartError(f"{path}: header column {index + 1} is empty ({why})")
        name = cell.strip()
        if name.lower() in TIME_NAMES:
            if time_column is not None:
                raise DvrkDartError(f"{path}: two time columns ({header[time_column].strip()}, column {time_column + 1}; {name}, "
                                    f"column {index + 1}): keep one")
            time_column = index
            continue
        key = _header_key(name, dvrk_joints)
        if key is None:
            known = "t or time, q1..q7, dq1..dq7, tau1..tau7" + (
                f", position|velocity|effort.<joint> (joints: {', '.join(dvrk_joints)})" if dvrk_joints else "")
            # a whole row in one cell: another separator (a name with a space, "t (ms)", is only a name)
            separator = next((f" (the columns are separated by commas; this file's by {words})"
                              for c, words in ((";", "';'"), ("\t", "tabs"), (" ", "spaces")) if c in name and len(header) == 1), "")
            unit = " (give the time in seconds, under the name t)" if not separator and name.lower().split()[0] in TIME_NAMES else ""
            if name.lower() in dvrk_joints:  # dvrk-dart excitation's CSV: time and bare joint names
                raise DvrkDartError(f"{path}: header column {index + 1} '{name}' is a bare joint name: a trajectory (positions only, "
                                    "as `dvrk-dart excitation` writes)? give it as --excitation; a measured run names "
                                    "position.<joint>, velocity.<joint>, effort.<joint>")
            shown = name if len(name) <= 40 else name[:37] + "..."
            raise DvrkDartError(f"{path}: header column {index + 1} '{shown}' is not a known name ({known}){separator}{unit}")
        field, joint, dvrk = key
        if (field, joint) in columns:
            raise DvrkDartError(f"{path}: header column {index + 1} '{name}': {field} of {joint} given twice")
        columns[(field, joint)] = index
        kinds.add(dvrk)
    if len(kinds) > 1:
        raise DvrkDartError(f"{path}: the header mixes the model's names (q1, ...) and the dVRK's joint names: use one")
    joints = tuple(j for j in JOINT_NAMES if any((f, j) in columns for f in FIELDS))
    for joint in joints:
        missing = [f for f in FIELDS if (f, joint) not in columns]
        if missing:
            dvrk = dvrk_joints[JOINT_NAMES.index(joint)] if kinds == {True} else None  # named as the header names it

            def named(fields):
                return ", ".join(f"{next(w for w, f in DVRK_FIELDS.items() if f == field)}.{dvrk}" if dvrk else f"{field}{joint[1:]}"
                                 for field in fields)

            given = [f for f in FIELDS if f not in missing]
            raise DvrkDartError(f"{path}: the header has {named(given)} without {named(missing)}: a joint needs its position, velocity "
                                "and effort (an effort not recorded: a column of zeros)")
    if not joints:
        raise DvrkDartError(f"{path}: the header names no joint")
    return CsvLayout(columns, time_column, joints, kinds == {True})


def headerless_layout(width: int, path: Path, coupled: tuple[int, ...] = ()) -> CsvLayout:
    """The layout of a file without a header; `coupled`: the arm's joints whose
    dVRK values mix (a partial log of them cannot be put in the model's coordinates)."""
    if width not in HEADERLESS_JOINTS:
        layouts = "; ".join(f"{n} columns ({', '.join(column_names_of(joints))})" for n, joints in HEADERLESS_JOINTS.items())
        raise DvrkDartError(f"{path}: {width} columns without a header row; known layouts: {layouts}; "
                            f"or a header row naming the columns (t, q1, dq1, tau1, ...){_semicolon_hint(path)}")
    joints = HEADERLESS_JOINTS[width]
    partly = [JOINT_NAMES[j] for j in coupled if JOINT_NAMES[j] in joints]
    if partly and len(partly) < len(coupled):
        raise DvrkDartError(f"{path}: {width} columns (joints {joints[0]}..{joints[-1]}), but this arm couples "
                            f"{', '.join(JOINT_NAMES[j] for j in coupled)} in the dVRK's values: log every coupled joint, "
                            "or give a header row")
    columns = {(field, joint): i * len(joints) + k for i, field in enumerate(FIELDS) for k, joint in enumerate(joints)}
    return CsvLayout(columns, None, joints, False)


def column_names_of(joints: tuple[str, ...]) -> list[str]:
    first, last = joints[0][1:], joints[-1][1:]
    return [f"{field}{first}..{field}{last}" for field in FIELDS]


def _numbers(raw: pd.DataFrame, names: list[str], path: Path, first_row: int) -> np.ndarray:
    """The cells as numbers; one line naming the first that is not a finite number."""
    values = raw.apply(pd.to_numeric, errors="coerce").to_numpy(dtype=float, copy=True)
    if np.all(np.isfinite(values)):
        return values
    # text that is no number comes first; a written "nan", "inf" or "NA" is a missing value, as an empty cell is
    text = np.isnan(values) & ~raw.map(is_missing).to_numpy()
    if text.any():
        row, col = np.argwhere(text)[0]
        raise DvrkDartError(f"{path}: {_row(row, first_row)}, column {names[col]}: '{raw.iat[row, col]}' is not a number")
    row, col = np.argwhere(~np.isfinite(values))[0]
    raise DvrkDartError(f"{path}: {_row(row, first_row)}, column {names[col]}: missing, NaN or infinite value")


def _row(index: int, first_row: int) -> str:
    """A data row as every message counts them (from 1), and its line in the file where a header shifts it."""
    return f"row {index + 1}" + (f" (line {index + first_row} of the file)" if first_row != 1 else "")


def rate_of_time_column(t: np.ndarray, path: Path, first_row: int) -> float:
    """Rows per second of an evenly spaced time column (s); one line naming the
    row that is not (`first_row`: the file line of the first data row)."""
    step = np.diff(t)
    if len(step) == 0 or not np.median(step) > 0:
        raise DvrkDartError(f"{path}: the time column does not increase")
    median = float(np.median(step))
    uneven = np.flatnonzero(np.abs(step - median) > TIME_JITTER * median)
    if len(uneven):
        # stamps rounded coarser than the step: every step near the median, many of them off it (a gap or a pause is one step far off)
        rounded = (f"; the stamps look rounded: {len(uneven) / len(step):.0%} of the steps are off, their mean is "
                   f"{float(t[-1] - t[0]) / len(step):.6g} s" if np.all(np.abs(step / median - 1.0) < 0.5) and len(uneven) > 0.1 * len(step) else "")
        raise DvrkDartError(f"{path}: time column, {_row(int(uneven[0]) + 1, first_row)}: a step of {step[uneven[0]]:.6g} s where the rows are "
                            f"{median:.6g} s apart{rounded} (rows must be evenly spaced, to {TIME_JITTER:.0%} of their step: resample "
                            "first, or drop the time column and give --rate)")
    # from the whole span, not one step: stamps far from zero (Unix time) are quantised to ~0.2 us, which moved
    # the median step, and with it a run's period, by 40 times the period's stated error
    return (len(t) - 1) / float(t[-1] - t[0])


@dataclass(frozen=True)
class CsvValues:
    """A CSV's values in the model's coordinates: (N, 21) q, dq, tau (zeros where not measured)."""

    values: np.ndarray
    measured: tuple[str, ...]  # the joints the file has columns of
    rate_hz: float | None  # from the time column, None without one
    unread: dict  # recorded joints read as not recorded -> why (`_constant_efforts`, `_dvrk_to_model`)


def read_csv_run(path: Path, motor_map, dvrk_joints: tuple[str, ...]) -> CsvValues:
    """Read a measured-run CSV in any of the module's layouts."""
    raw = _read_text(path)
    header = _has_header(raw)
    if header:
        layout = layout_from_header(list(raw.iloc[0]), path, dvrk_joints)
        names = [str(cell).strip() for cell in raw.iloc[0]]  # a column named as the file names it
        raw = raw.iloc[1:].reset_index(drop=True)
    else:
        if raw.shape[1] - 1 in HEADERLESS_JOINTS and raw.iloc[:, -1].isna().all():  # every line ends with a separator
            raise DvrkDartError(f"{path}: {raw.shape[1]} columns without a header row, the last one empty on every row: "
                                f"a trailing comma? ({raw.shape[1] - 1} columns is a known layout)")
        layout = headerless_layout(raw.shape[1], path, _coupled_joints(motor_map))
        names = [""] * raw.shape[1]
        for (field, joint), index in layout.columns.items():
            names[index] = f"{field}{joint[1:]}"
    file_values = _numbers(raw, names, path, 2 if header else 1)
    if not len(file_values):
        raise DvrkDartError(f"{path}: a header row and no data rows")
    values = np.zeros((len(file_values), 3 * N_JOINTS))
    for (field, joint), index in layout.columns.items():
        values[:, FIELDS.index(field) * N_JOINTS + JOINT_NAMES.index(joint)] = file_values[:, index]
    unread = _constant_efforts(file_values, layout, _coupled_joints(motor_map))
    if layout.dvrk_names:
        values, undetermined = _dvrk_to_model(values, layout.joints, motor_map, dvrk_joints)
        unread.update(undetermined)
    if layout.time_column is not None and len(file_values) < MIN_TIME_ROWS:
        raise DvrkDartError(f"{path}: {len(file_values)} data rows: a time column needs at least {MIN_TIME_ROWS}")
    rate = None if layout.time_column is None else rate_of_time_column(file_values[:, layout.time_column], path, 2 if header else 1)
    return CsvValues(values, layout.joints, rate, unread)


def _constant_efforts(file_values: np.ndarray, layout: CsvLayout, coupled: tuple[int, ...]) -> dict[str, str]:
    """The layout's joints whose effort column (in the file, before any
    coupling) never changes, each with why: zeros padding a layout, or a
    logger that did not read it. No current sensor reads one value for a whole
    run; such a column set the periodic band of every joint and gave figures
    against zero. A coupled dVRK joint's lost effort takes its partners' with it."""
    column = {joint: file_values[:, [layout.columns[(field, joint)] for field in FIELDS]] for joint in layout.joints}
    constant = {joint: "every value zero" if not column[joint].any() else "the effort never changes"
                for joint in layout.joints if np.ptp(column[joint][:, 2]) == 0.0}
    if layout.dvrk_names:
        partners = [JOINT_NAMES[j] for j in coupled if JOINT_NAMES[j] in layout.joints]
        lost = [joint for joint in partners if joint in constant]
        constant.update({joint: f"coupled to {', '.join(lost)}, whose effort never changes" for joint in partners
                         if lost and joint not in constant})
    return constant


def joints_with_efforts(read: CsvValues, path: Path) -> tuple[tuple[str, ...], list[str]]:
    """(the joints read as recorded, the note on the others): those whose
    effort never changes (`_constant_efforts`, positions kept) or whose model
    coordinate the file does not give (`_dvrk_to_model`) are not recorded."""
    by_why: dict[str, list[str]] = {}
    for joint, why in read.unread.items():
        by_why.setdefault(why, []).append(joint)
    said = "; ".join(f"{', '.join(joints)}: {why}" for why, joints in by_why.items())
    if len(read.unread) == len(read.measured):
        raise DvrkDartError(f"{path}: no joint's effort can be read ({said})")
    return (tuple(joint for joint in read.measured if joint not in read.unread),
            [f"{path}: {said}: read as not recorded"] if said else [])


def still_position_notes(values: np.ndarray, measured: tuple[str, ...], path: Path) -> list[str]:
    """A recorded joint whose position holds one value for the whole run while its effort changes (its velocity
    column whatever it holds): held there (a brake, a servo at rest), or a position the logger did not read. Every joint's
    model efforts use that value (q3 left at 0 doubled q1's and q2's figures on a 2018 run), so it is said."""
    notes = []
    if not any(np.ptp(values[:, JOINT_NAMES.index(name)]) > 0.0 for name in measured):
        return notes  # a still arm: what it cannot be diagnosed for is said once, elsewhere
    for name in measured:
        j = JOINT_NAMES.index(name)
        q, tau = values[:, j], values[:, 2 * N_JOINTS + j]
        if np.ptp(q) == 0.0 and np.ptp(tau) > 0.0:
            notes.append(f"{path}: {name}'s position is {q[0]:g} for the whole run while its effort changes: held there, or its "
                         f"position not logged? every joint's model efforts use {name} = {q[0]:g}")
    return notes


def say_once(notes: list[str]) -> None:
    """Notes on stderr, each once per process (a command may read a file more than once)."""
    for note in notes:
        if note in _NOTES_SAID:
            continue
        _NOTES_SAID.add(note)
        if _NOTE_SINKS:
            _NOTE_SINKS[-1].append(note)
        else:
            print(f"dvrk-dart: note: {note}", file=sys.stderr)


@contextmanager
def notes_kept(into: list[str]):
    """The notes said inside go into `into`, not stderr: for a stage that reads
    runs it made itself (the blind suite), whose notes belong in its own output."""
    _NOTE_SINKS.append(into)
    try:
        yield into
    finally:
        _NOTE_SINKS.pop()


def _coupled_joints(motor_map) -> tuple[int, ...]:
    columns = motor_map.columns
    return tuple(range(N_JOINTS)[columns]) if isinstance(columns, slice) else tuple(int(c) for c in columns)


def _dvrk_to_model(values: np.ndarray, joints: tuple[str, ...], motor_map, dvrk_joints: tuple[str, ...]) -> tuple[np.ndarray, dict]:
    """The dVRK's joint values -> the model's coordinates, and the logged joints
    coupled to one the file does not log, each with why (their columns zeroed:
    a PSM log without the jaw gives q1..q4, `MotorCoordinateMap.determined_by`)."""
    logged = np.array([name in joints for name in JOINT_NAMES])
    determined = motor_map.determined_by(logged)
    q, dq, tau = (values[:, i * N_JOINTS:(i + 1) * N_JOINTS] for i in range(3))
    model = np.hstack([motor_map.positions_to_model(q), motor_map.positions_to_model(dq), motor_map.efforts_to_model(tau)])
    model[:, np.tile(~determined, 3)] = 0.0
    missing = ", ".join(dvrk_joints[j] for j in _coupled_joints(motor_map) if not logged[j])
    return model, {name: f"coupled to the dVRK's {missing}, not logged"
                   for name, known in zip(JOINT_NAMES, determined) if name in joints and not known}
