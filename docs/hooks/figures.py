"""MkDocs hook: the figures of the last validation, never typed.

The pages (docs/*.md) explain without run figures, so that they read as
checked in; this hook builds one more page, `last-validation.md`, from
`last-validation.template` beside it. The template writes `{{ out: FILE : KEY.PATH }}`: the value at KEY.PATH of the JSON
file FILE under the validation's output folder (`out/`, or $DVRK_DART_OUT),
rendered at build time; the images of `IMAGES` are copied from there. A list shows its first three entries (J1..J3) as
"a / b / c"; `KEY[i]` picks one entry. `{{ out-source }}` says which
validation the figures come from (its date, from out/campaign.json). A figure
that is not there (no validation yet) renders as "not measured (run `make
validate`)", or `make bench` for bench.json's: the site still builds.
"""

from __future__ import annotations

import datetime
import json
import os
import re
from pathlib import Path

FIGURE = re.compile(r"\{\{\s*out:\s*([^:}]+?)\s*:\s*([^}]+?)\s*\}\}")
SOURCE = re.compile(r"\{\{\s*out-source\s*\}\}")
MISSING = "not measured (run `make validate`)"
#: files another make target writes than validate (file -> target)
WRITTEN_BY = {"bench.json": "make bench"}
#: images a page shows, taken from the validation's outputs at build time (site path -> path under out/)
IMAGES = {"assets/repeatable_residual_one_period.png": "periodic/repeatable_residual_one_period.png"}
#: a 1x1 grey PNG standing in for an image no validation has made yet
PLACEHOLDER_PNG = bytes.fromhex(
    "89504e470d0a1a0a0000000d4948445200000001000000010800000000"
    "3a7e9b550000000a49444154789c6360600000000400015c2d4d3b0000000049454e44ae426082")
SHOWN_ENTRIES = 3
DIGITS = 3


def _out_dir() -> Path:
    return Path(os.environ.get("DVRK_DART_OUT", Path(__file__).resolve().parents[2] / "out"))


def _lookup(data, path: str):
    for part in path.split("."):
        match = re.fullmatch(r"([^\[]+)((?:\[\d+\])*)", part)
        if match is None:
            return None
        data = data.get(match.group(1)) if isinstance(data, dict) else None
        for index in re.findall(r"\[(\d+)\]", match.group(2)):
            data = data[int(index)] if isinstance(data, list) and int(index) < len(data) else None
    return data


def _number(value) -> str:
    return f"{value:.{DIGITS}g}" if isinstance(value, float) else str(value)


def render(value) -> str:
    if value is None:
        return MISSING
    if isinstance(value, list):
        return " / ".join(_number(v) for v in value[:SHOWN_ENTRIES])
    return _number(value)


def figure(file: str, key: str) -> str:
    path = _out_dir() / file
    missing = MISSING.replace("make validate", WRITTEN_BY.get(file, "make validate"))
    try:
        value = _lookup(json.loads(path.read_text(encoding="utf-8")), key)
    except (OSError, ValueError):
        return missing
    return missing if value is None else render(value)


def source() -> str:
    campaign = _out_dir() / "campaign.json"
    if not campaign.is_file():
        return "no validation has run yet here (`make validate` writes `out/`)"
    when = datetime.datetime.fromtimestamp(campaign.stat().st_mtime, datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    return f"the validation of {when} (`make validate`, folder `out/`)"


TEMPLATE = Path(__file__).with_name("last-validation.template")


def on_files(files, config):
    from mkdocs.structure.files import File

    files.append(File.generated(config, "last-validation.md", content=TEMPLATE.read_text(encoding="utf-8")))
    for site_path, out_path in IMAGES.items():
        source = _out_dir() / out_path
        content = source.read_bytes() if source.is_file() else PLACEHOLDER_PNG
        files.append(File.generated(config, site_path, content=content))
    return files


def on_page_markdown(markdown: str, page, config, files) -> str:
    markdown = SOURCE.sub(lambda m: source(), markdown)
    return FIGURE.sub(lambda m: figure(m.group(1), m.group(2)), markdown)
