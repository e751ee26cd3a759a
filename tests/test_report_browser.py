"""The report as a reader sees it: opened in headless Chromium, every image
loads, nothing is written to the console, and the page renders.

Skipped when Chromium is absent (Debian: `apt-get install chromium`), except
in CI (CI=true), where .ci/run installs it and its absence fails the test.
`make check-report` runs this file alone.
"""

from __future__ import annotations

import dataclasses
import html
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest
from report_runs import synthetic_torque_record, synthetic_velocity_record, write_run

from dvrk_dart.analysis.report import REPORT_FILE, build_report

CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome")
CHROMIUM = next((found for name in CHROMIUM_NAMES if (found := shutil.which(name))), None)
#: in CI (CI=true) the browser is installed by .ci/run: its absence is a failure, not a skip
REQUIRED = os.environ.get("CI", "").lower() == "true"
if CHROMIUM is None and REQUIRED:
    pytest.fail(f"CI=true but headless Chromium is not installed (none of {', '.join(CHROMIUM_NAMES)} on PATH)", pytrace=False)
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason=f"headless Chromium not installed (none of {', '.join(CHROMIUM_NAMES)} on PATH)")

BROWSER_TIMEOUT_S = 90
#: simulated time the page gets to load its images before the DOM is dumped
VIRTUAL_TIME_BUDGET_MS = 10_000
WINDOW = "1300,2400"
#: appended to a *copy* of the report: records on <body> which images did not load
PROBE = """<script>
window.addEventListener('load', () => {
  const broken = [...document.images].filter(i => !i.complete || i.naturalWidth === 0).map(i => i.getAttribute('src'));
  document.body.setAttribute('data-probe-images', String(document.images.length));
  document.body.setAttribute('data-probe-broken', JSON.stringify(broken));
});
</script>"""
CONSOLE_LINE = re.compile(r":CONSOLE[:(]")


def chromium(tmp_path: Path, page: Path, *extra: str) -> subprocess.CompletedProcess:
    profile = tmp_path / f"profile-{len(list(tmp_path.glob('profile-*')))}"
    return subprocess.run(
        [
            CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
            "--disable-background-networking", "--disable-component-update", "--disable-sync",
            f"--user-data-dir={profile}", "--enable-logging=stderr", "--v=0", f"--window-size={WINDOW}",
            f"--virtual-time-budget={VIRTUAL_TIME_BUDGET_MS}", *extra, page.as_uri(),
        ],
        capture_output=True, text=True, timeout=BROWSER_TIMEOUT_S,
    )


def probe(tmp_path: Path, report_dir: Path, name: str) -> tuple[int, list[str], list[str]]:
    """(images on the page, images that failed to load, console lines) of a probed copy."""
    copy = tmp_path / name
    shutil.copytree(report_dir, copy)
    page = copy / REPORT_FILE
    page.write_text(page.read_text().replace("</body>", PROBE + "</body>"))
    done = chromium(tmp_path, page, "--dump-dom")
    assert done.returncode == 0, done.stderr[-2000:]
    count = re.search(r'data-probe-images="(\d+)"', done.stdout)
    broken = re.search(r'data-probe-broken="([^"]*)"', done.stdout)
    assert count and broken, "the probe did not run: page not loaded?"
    console = [line for line in done.stderr.splitlines() if CONSOLE_LINE.search(line)]
    return int(count.group(1)), json.loads(html.unescape(broken.group(1))), console


@pytest.fixture(scope="module")
def report_dir(tmp_path_factory) -> Path:
    runs = tmp_path_factory.mktemp("runs")
    write_run(synthetic_torque_record(), runs)
    write_run(synthetic_velocity_record(), runs)
    kinematic = dataclasses.replace(synthetic_torque_record(), name="rectilinear_kinematic_cw-on", effort_command=None)
    kinematic.config = {**kinematic.config, "mode": "kinematic"}
    write_run(kinematic, runs)
    out = tmp_path_factory.mktemp("out") / "report"
    build_report(runs, out, jobs=1)
    return out


def test_every_image_loads_and_the_console_is_clean(report_dir, tmp_path):
    images, broken, console = probe(tmp_path, report_dir, "as-built")
    assert images >= 2
    assert broken == [], f"images that did not load: {broken}"
    assert console == [], "console messages:\n" + "\n".join(console)


def test_the_probe_sees_a_missing_image(report_dir, tmp_path):
    """Negative control: the check above can fail."""
    damaged = tmp_path / "damaged-source"
    shutil.copytree(report_dir, damaged)
    next((damaged / "figures").glob("*.png")).unlink()
    _, broken, _ = probe(tmp_path, damaged, "damaged")
    assert len(broken) == 1


def test_the_page_renders(report_dir, tmp_path):
    shot = tmp_path / "report.png"
    done = chromium(tmp_path, report_dir / REPORT_FILE, f"--screenshot={shot}")
    assert done.returncode == 0 and shot.is_file(), done.stderr[-2000:]
    pixels = matplotlib.image.imread(shot)
    assert pixels.shape[0] > 500 and pixels.shape[1] > 500
    # a rendered page has text, tables and figures: far from a blank screen
    assert np.std(pixels[..., :3]) > 0.05


def test_the_report_leads_to_the_documentation(tmp_path_factory, tmp_path, monkeypatch):
    """The report's link to the docs opens the documentation site (built here with --strict)."""
    import sys

    site = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1", "DVRK_DART_OUT": str(tmp_path / "no-out")}
    built = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(site)],
                           cwd=Path(__file__).resolve().parents[1], env=env, capture_output=True, text=True, timeout=300)
    assert built.returncode == 0, built.stderr[-2000:]
    monkeypatch.setenv("DVRK_DART_SITE", str(site))
    runs = tmp_path / "runs"
    write_run(synthetic_velocity_record(), runs)
    report = tmp_path / "report"
    build_report(runs, report, jobs=1)
    dom = chromium(tmp_path, report / REPORT_FILE, "--dump-dom")
    link = re.search(r'<a id="documentation" href="([^"]+)"', dom.stdout)
    assert link, "no documentation link in the report"
    target = (report / html.unescape(link.group(1))).resolve()
    assert target == (site / "index.html").resolve()
    docs = chromium(tmp_path, target, "--dump-dom")
    assert docs.returncode == 0 and "<title>dvrk_dart</title>" in docs.stdout, docs.stdout[:500]
    # two clicks from there: the page on bags of PSM2, and what payload.gravity_efforts_at_q0_interval means
    assert "your-own-dvrk/" in docs.stdout and "outputs/" in docs.stdout
    assert "--arm PSM2" in (site / "your-own-dvrk" / "index.html").read_text()
    assert "gravity_efforts_at_q0_interval" in (site / "outputs" / "index.html").read_text()
