"""The layers import downward only: import-linter with pyproject.toml's contract."""

import shutil
import subprocess
import sys
from pathlib import Path

from dvrk_dart.paths import PROJECT_DIR


def test_the_layer_contract_holds():
    lint = shutil.which("lint-imports") or str(Path(sys.executable).parent / "lint-imports")
    done = subprocess.run([lint, "--config", str(PROJECT_DIR / "pyproject.toml")], cwd=PROJECT_DIR, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    assert "0 broken" in done.stdout


def test_no_module_keeps_the_arm_or_the_reading_options_in_ambient_state():
    """The arm is passed explicitly: no context variable, no module-level current arm."""
    import ast

    for path in (PROJECT_DIR / "dvrk_dart").rglob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        imported = {alias.name for node in ast.walk(tree) if isinstance(node, (ast.Import, ast.ImportFrom))
                    for alias in node.names} | {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
        assert "contextvars" not in imported, path
