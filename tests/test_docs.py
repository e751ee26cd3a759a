"""The documentation: the site builds with --strict, every path a model card,
a data file or a page names exists, every key the outputs hold is documented,
and the README stays a short entry point without a figure a run produces."""

import json
import os
import re
import subprocess
import sys

import pytest

from dvrk_dart.paths import PROJECT_DIR

DOCUMENTS = [*PROJECT_DIR.glob("models/**/*.md"), *PROJECT_DIR.glob("models/**/*.toml"), *PROJECT_DIR.glob("pipelines/**/*.toml"),
             *PROJECT_DIR.glob("reference_data/*"), *PROJECT_DIR.glob("docs/*.md"), PROJECT_DIR / "README.md"]
PROJECT_PATH = re.compile(r"(?<![\w/.-])((?:dvrk_dart|models|pipelines|reference_data|tests|docs)/[\w./-]*\w)")
README_MAX_LINES = 130


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda p: str(p.relative_to(PROJECT_DIR)))
def test_every_path_a_document_names_exists(document):
    text = document.read_text(encoding="utf-8")
    missing = [p for p in PROJECT_PATH.findall(text) if not (PROJECT_DIR / p).exists() and "<" not in p and "*" not in p]
    assert not missing, f"{document.name} names {missing}"


def test_the_site_builds_strict(tmp_path):
    """mkdocs --strict: no broken link or reference; the figures come from an out/ folder (here an empty one: 'not measured')."""
    env = {**os.environ, "DVRK_DART_OUT": str(tmp_path / "out"), "NO_MKDOCS_2_WARNING": "1"}
    site = tmp_path / "site"
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(site)], cwd=PROJECT_DIR, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert (site / "index.html").is_file() and (site / "api" / "index.html").is_file()
    assert "doc-function" in (site / "api" / "index.html").read_text()  # mkdocstrings rendered the docstrings
    assert "not measured (run" in (site / "last-validation" / "index.html").read_text()


@pytest.mark.parametrize("document", [*PROJECT_DIR.glob("docs/*.md"), PROJECT_DIR / "README.md"], ids=lambda p: p.name)
def test_pages_read_as_checked_in(document):
    """No figure placeholder in a page a browser of the repository opens, and no image link to a file the repository lacks."""
    text = document.read_text(encoding="utf-8")
    assert "{{ out" not in text
    for image in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text):
        assert image.startswith("http") or (document.parent / image).is_file(), image


def test_figures_are_rendered_from_the_validation_outputs(tmp_path, monkeypatch):
    sys.path.insert(0, str(PROJECT_DIR / "docs" / "hooks"))
    import figures

    (tmp_path / "periodic").mkdir()
    (tmp_path / "periodic" / "periodic.json").write_text(json.dumps({"model_vs_measured_two": {"periodic": [0.0465, 0.0957, 0.1343, 1.0]}}))
    monkeypatch.setenv("DVRK_DART_OUT", str(tmp_path))
    page = figures.on_page_markdown("J1..J3 {{ out: periodic/periodic.json : model_vs_measured_two.periodic }}, "
                                    "J2 {{ out: periodic/periodic.json : model_vs_measured_two.periodic[1] }}, "
                                    "{{ out: periodic/periodic.json : nothing }}", None, None, None)
    assert page == "J1..J3 0.0465 / 0.0957 / 0.134, J2 0.0957, not measured (run `make validate`)"
    assert figures.on_page_markdown("{{ out: bench.json : diagnose_s }}", None, None, None) == "not measured (run `make bench`)"


def test_every_output_key_is_documented(tmp_path):
    """The top-level keys of the outputs the tests' own runs write appear in docs/outputs.md."""
    from dvrk_dart.cli import main

    outputs = (PROJECT_DIR / "docs" / "outputs.md").read_text()
    assert main(["replay", "--measured", "two", "--duration", "0.2", "--out", str(tmp_path / "run")]) == 0
    assert main(["uncertainty", "--measured", "two", "--samples", "2", "--duration", "0.2", "--out", str(tmp_path / "mc")]) == 0
    assert main(["identify", "--runs", "one", "--out", str(tmp_path / "id")]) == 0
    files = [tmp_path / "run" / "metrics.json", tmp_path / "run" / "config.json", tmp_path / "mc" / "uncertainty.json",
             tmp_path / "id" / "identification.json"]
    undocumented = {f.name: [k for k in json.loads(f.read_text()) if f"`{k}`" not in outputs] for f in files}
    assert not any(undocumented.values()), undocumented


def test_the_readme_is_a_short_entry_point():
    readme = (PROJECT_DIR / "README.md").read_text()
    assert len(readme.splitlines()) <= README_MAX_LINES
    assert readme.splitlines()[3].startswith("make validate") and readme.splitlines()[4].startswith("make test")
    # no figure a run produces: no decimal numbers with an effort, length or time unit
    assert not re.findall(r"\d\.\d+\s*(?:N·m|N\b|m\b|s\b|kg|rad)", readme)
