"""The project's HTML, below every page that uses it (the report, the
diagnosis page, the identification page): the Jinja2 templates of
dvrk_dart/templates/ (autoescaped: every value is escaped unless it is
already `Markup`), the page style, number formatting, and table cells that
carry their exact value and identity in data-* attributes."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import jinja2
from markupsafe import Markup

#: the templates of every page and table (autoescaped; a missing variable is an error, not an empty string)
TEMPLATES = jinja2.Environment(loader=jinja2.PackageLoader("dvrk_dart", "templates"), autoescape=True,
                               undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True)

#: significant digits shown in the tables (the exact value is in data-value)
SHOWN_DIGITS = 4
RATIO_DIGITS = 3

STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1300px; padding: 0 1em; color: #222; }
h1 { margin-bottom: 0.2em; } h2 { border-bottom: 1px solid #ccc; padding-bottom: 0.2em; margin-top: 2em; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.88em; }
th, td { border: 1px solid #ddd; padding: 0.25em 0.55em; text-align: left; vertical-align: top; }
th { background: #f4f4f4; } td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
tr.pass td.status { background: #dff5df; } tr.fail td.status { background: #fbdede; } tr.missing td.status { background: #fff1cc; }
td.better { background: #eef8ee; } td.worse { background: #fdf0f0; }
figure { margin: 1.5em 0; } figure img { max-width: 100%; border: 1px solid #eee; }
figcaption { font-size: 0.9em; color: #444; } .note { color: #555; font-size: 0.9em; }
details { margin: 0.3em 0; } pre { background: #f8f8f8; padding: 0.6em; overflow-x: auto; font-size: 0.8em; }
.summary { font-size: 1.15em; padding: 0.6em 1em; border-radius: 4px; display: inline-block; }
.summary.ok { background: #dff5df; } .summary.ko { background: #fbdede; }
"""


# ---------------------------------------------------------------- small HTML helpers


#: `digits` value of a count (samples): shown in full
INTEGER = 0


def fmt(value: float, digits: int = SHOWN_DIGITS) -> str:
    """A number as shown in a table: `digits` significant digits (INTEGER: a count); '—' when missing."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "—"
    if math.isinf(value):
        return "∞" if value > 0 else "-∞"
    if digits == INTEGER:
        return str(int(round(value)))
    return f"{value:.{digits}g}"


DIMENSIONLESS = "1"


def unit_text(unit: str) -> str:
    """A unit as shown: a ratio's unit "1" reads as a number in a table."""
    return "dimensionless" if unit == DIMENSIONLESS else unit


def render(template: str, **context) -> Markup:
    """A template of dvrk_dart/templates/ rendered with `context` (the page style included)."""
    return Markup(TEMPLATES.get_template(template).render(style=Markup(STYLE), **context))


@dataclass(frozen=True)
class Cell:
    """A table cell: its text (escaped unless `Markup`), CSS class, data-*
    attributes (name, value), and whether it is code (with a hover title)."""

    text: object
    css: str = ""
    data: tuple[tuple[str, str], ...] = ()
    code: bool = False
    title: str = ""


@dataclass(frozen=True)
class Row:
    cells: tuple[Cell, ...]
    css: str = ""


def num_cell(value: float, digits: int = SHOWN_DIGITS, css: str = "", **attrs) -> Cell:
    """A number as shown, with its exact value in data-value and what it is in the other data-* attributes."""
    exact = repr(float(value)) if value is not None else "nan"
    return Cell(fmt(value, digits), f"num {css}".strip(), (*((k, str(v)) for k, v in attrs.items()), ("value", exact)))


def text_cell(text: object, css: str = "") -> Cell:
    return Cell(text, css)


def code_cell(text: object, title: str = "") -> Cell:
    return Cell(text, code=True, title=title)


def row(*cells: Cell, css: str = "") -> Row:
    return Row(tuple(cells), css)


def table(header: Sequence[str], rows: Iterable[Row | Sequence[Cell]], css: str = "data") -> Markup:
    """A table of `rows` (a Row, or a sequence of cells) under `header` (templates/table.html)."""
    return render("table.html", header=header, rows=[r if isinstance(r, Row) else Row(tuple(r)) for r in rows], css=css)
