"""What the tests of real recordings share: the 2018 dataset's paths, CSVs
written with a header from a loaded run, and the CLI's JSON or one-line refusal."""

import json
from pathlib import Path

import pandas as pd
import pytest

from dvrk_dart.cli import main
from dvrk_dart.io.reference_data import SHARED_ROOT

DATA_2018 = SHARED_ROOT / "wpi-2018"
TEST1, TEST2 = DATA_2018 / "psm1_fourier_test1.csv", DATA_2018 / "psm1_fourier_test2.csv"
needs_2018 = pytest.mark.skipif(not TEST1.is_file(), reason="the 2018 dataset (../shared/reference_data/wpi-2018) is not here")


def cli_json(capsys, *args) -> dict:
    capsys.readouterr()
    assert main([*args, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def write_header_csv(path: Path, run, columns: list[str], t: bool = True) -> Path:
    table = {"t": run.t}
    for name in columns:
        field, joint = name.rstrip("1234567"), int(name[-1]) - 1
        table[name] = {"q": run.q, "dq": run.dq, "tau": run.tau}[field][:, joint]
    frame = pd.DataFrame({k: v for k, v in table.items() if t or k != "t"})
    frame.to_csv(path, index=False)
    return path


def columns_of(*joints: int) -> list[str]:
    """A header's q, dq and tau columns of the joints given (1-based)."""
    return [f"{field}{j}" for j in joints for field in ("q", "dq", "tau")]


def refusal(capsys, *argv: str) -> str:
    """The one line a refused command prints (exit 2)."""
    capsys.readouterr()
    assert main(list(argv)) == 2
    [line] = capsys.readouterr().err.strip().splitlines()
    return line
