"""Where the project's data folders are, relative to the installed package
(an editable install: the package sits at the top of the checkout)."""

from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
PROJECT_DIR = PACKAGE_DIR.parent
MODELS_DIR = PROJECT_DIR / "models"
PIPELINES_DIR = PROJECT_DIR / "pipelines"
