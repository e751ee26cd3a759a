"""Small HTML helpers of the report: the page style, number formatting, and
table cells that carry their exact value and identity in data-* attributes."""

from __future__ import annotations

import html
import math
from collections.abc import Iterable, Sequence

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


def _e(text: object) -> str:
    return html.escape(str(text), quote=True)


def _attrs(attrs: dict) -> str:
    return "".join(f' data-{k}="{_e(v)}"' for k, v in attrs.items())


def num_cell(value: float, digits: int = SHOWN_DIGITS, css: str = "", **attrs) -> str:
    exact = repr(float(value)) if value is not None else "nan"
    classes = f"num {css}".strip()
    return f'<td class="{classes}"{_attrs(attrs)} data-value="{exact}">{fmt(value, digits)}</td>'


def text_cell(text: object, css: str = "") -> str:
    return f'<td class="{css}">{_e(text)}</td>' if css else f"<td>{_e(text)}</td>"


def code_cell(text: object, title: str = "") -> str:
    title_attr = f' title="{_e(title)}"' if title else ""
    return f"<td><code{title_attr}>{_e(text)}</code></td>"


def table(header: Sequence[str], rows: Iterable[str], css: str = "data") -> str:
    head = "".join(f"<th>{_e(h)}</th>" for h in header)
    return f'<table class="{css}"><thead><tr>{head}</tr></thead><tbody>{"".join(rows)}</tbody></table>'
