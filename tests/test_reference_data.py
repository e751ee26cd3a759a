"""Reference data: resolver order, checksums, download, and malformed input."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io import reference_data
from dvrk_dart.io.reference_data import load_run, resolve, resolve_run
from arms import PSM


def test_loader_returns_named_typed_columns():
    run = load_run(resolve_run("two"), PSM)
    assert list(run.data.columns[:3]) == ["t", "q1", "q2"] and run.data.columns[-1] == "tau7"
    assert run.data.shape == (5999, 22)
    assert all(dtype == np.float64 for dtype in run.data.dtypes)
    assert run.t[1] == pytest.approx(1 / 200)


def _cli_error(path):
    out = subprocess.run(
        [sys.executable, "-m", "dvrk_dart.cli", "model-errors", "--measured", str(path)],
        capture_output=True, text=True,
    )
    return out.returncode, out.stderr


def _write_rows(path, rows):
    path.write_text("\n".join(",".join(str(v) for v in r) for r in rows) + "\n")
    return path


GOOD_ROW = [0.1] * 21


@pytest.mark.parametrize(
    "content, message",
    [
        (None, "file not found"),
        ([[0.1] * 20] * 100, "20 columns without a header row; known layouts: 21 columns"),
        ([GOOD_ROW] * 50 + [[0.1] * 5 + ["abc"] + [0.1] * 15] + [GOOD_ROW] * 49, "row 51, column q6: 'abc' is not a number"),
        ([GOOD_ROW] * 10 + [[0.1] * 14 + ["nan"] + [0.1] * 6] + [GOOD_ROW] * 89, "row 11, column tau1: missing, NaN or infinite"),
        ([GOOD_ROW] * 10, "10 rows, at least 410 needed"),
        ("", "file is empty"),
    ],
)
def test_malformed_runs_give_one_line_errors(tmp_path, content, message):
    path = tmp_path / "run.csv"
    if isinstance(content, list):
        _write_rows(path, content)
    elif content == "":
        path.write_text("")
    code, stderr = _cli_error(path)
    assert code == 2
    assert stderr.count("\n") == 1 and "Traceback" not in stderr
    assert message in stderr and str(path) in stderr


def test_bad_checksum_is_refused(tmp_path, monkeypatch):
    shutil.copy(resolve("two_results.csv"), tmp_path / "two_results.csv")
    with open(tmp_path / "two_results.csv", "a") as f:
        f.write("0" + ",0" * 20 + "\n")
    monkeypatch.setenv(reference_data.ENV_DATA_DIR, str(tmp_path))
    with pytest.raises(DvrkDartError, match="does not match the manifest"):
        resolve("two_results.csv")
    env = dict(os.environ, **{reference_data.ENV_DATA_DIR: str(tmp_path)})
    out = subprocess.run([sys.executable, "-m", "dvrk_dart.cli", "model-errors", "--measured", "two"], capture_output=True, text=True, env=env)
    errors = [line for line in out.stderr.splitlines() if not line.startswith("dvrk-dart: note:")]  # params.json: read elsewhere, said
    assert out.returncode == 2 and len(errors) == 1 and "sha256" in errors[0], out.stderr


def test_environment_variable_wins_over_shared_folder(tmp_path, monkeypatch):
    shutil.copy(resolve("params.json"), tmp_path / "params.json")
    monkeypatch.setenv(reference_data.ENV_DATA_DIR, str(tmp_path))
    assert resolve("params.json") == tmp_path / "params.json"


def test_download_from_pinned_commit_with_checksum(tmp_path, monkeypatch):
    """The download path, against a local mirror laid out like the upstream repository."""
    mirror = tmp_path / "mirror"
    entry = reference_data.manifest()["files"]["params.json"]
    target = mirror / entry["path"]
    target.parent.mkdir(parents=True)
    shutil.copy(resolve("params.json"), target)
    monkeypatch.setenv(reference_data.ENV_URL_TEMPLATE, f"file://{mirror}/{{path}}")
    monkeypatch.setenv(reference_data.ENV_CACHE_DIR, str(tmp_path / "cache"))
    monkeypatch.setattr(reference_data, "SHARED_ROOT", tmp_path / "absent")
    monkeypatch.delenv(reference_data.ENV_DATA_DIR, raising=False)
    path = resolve("params.json")
    assert path.parent.parent == tmp_path / "cache" and path.is_file()
    # a corrupted mirror is refused and leaves nothing in the cache
    path.unlink()
    target.write_text("{}")
    with pytest.raises(DvrkDartError, match="sha256"):
        resolve("params.json")
    assert not any((tmp_path / "cache").rglob("params.json"))


def test_a_download_that_cannot_be_made_is_one_line_naming_what_to_correct(tmp_path, monkeypatch):
    """A URL template without a scheme or with a wrong placeholder, a connection cut mid-file and a server that
    is not HTTP ended in tracebacks; an empty DVRK_DART_CACHE downloaded into the current folder."""
    import http.client
    import urllib.request

    monkeypatch.setattr(reference_data, "SHARED_ROOT", tmp_path / "absent")
    monkeypatch.delenv(reference_data.ENV_DATA_DIR, raising=False)
    monkeypatch.setenv(reference_data.ENV_CACHE_DIR, str(tmp_path / "cache"))
    for template, words in (("/no/scheme/{path}", "unknown url type"), ("file:///m/{repo}/{path}", "not a URL template"),
                            ("file:///m/{repository/{path}", "not a URL template")):
        monkeypatch.setenv(reference_data.ENV_URL_TEMPLATE, template)
        with pytest.raises(DvrkDartError, match=words):
            resolve("params.json")

    def cut(url, timeout):
        raise http.client.IncompleteRead(b"x" * 10, 100)

    monkeypatch.setenv(reference_data.ENV_URL_TEMPLATE, "http://127.0.0.1:9/{path}")
    monkeypatch.setattr(urllib.request, "urlopen", cut)
    with pytest.raises(DvrkDartError, match=r"params.json: not found in .* and download from http://127.0.0.1:9/.* failed \(IncompleteRead"):
        resolve("params.json")
    assert not any((tmp_path / "cache").rglob("params.json*"))
    link = reference_data.cache_dir("params.json") / "params.json"
    link.parent.mkdir(parents=True, exist_ok=True)
    link.symlink_to(tmp_path / "nowhere")  # the user's link: a download never replaces it
    with pytest.raises(DvrkDartError, match="a link in the download cache"):
        resolve("params.json")
    assert link.is_symlink()
    monkeypatch.setenv(reference_data.ENV_CACHE_DIR, "")
    assert reference_data.cache_dir("params.json").parent == Path.home() / ".cache" / "dvrk_dart"


def test_a_data_folder_laid_out_as_the_shared_one_is_read_and_one_without_the_file_is_said(tmp_path, monkeypatch, capsys):
    """DVRK_REFERENCE_DATA=../shared/reference_data (wpi-mtm/, wpi-2018/) fell back to a download; a folder without
    the file was passed over without a word."""
    (tmp_path / "wpi-mtm").mkdir()
    shutil.copy(resolve("mtm/params.json"), tmp_path / "wpi-mtm" / "params.json")
    monkeypatch.setenv(reference_data.ENV_DATA_DIR, str(tmp_path))
    assert resolve("mtm/params.json") == tmp_path / "wpi-mtm" / "params.json"
    path = resolve("two_results.csv")
    assert path != tmp_path / "two_results.csv" and path.is_file()
    assert f"DVRK_REFERENCE_DATA={tmp_path} holds neither two_results.csv nor wpi/two_results.csv: read {path}" in capsys.readouterr().err
