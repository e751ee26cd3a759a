"""The report's section on parameter uncertainty: the band of simulated
efforts over the parameter samples, the measured efforts in it, per joint."""

from __future__ import annotations

import json
from pathlib import Path

from dvrk_dart.io.html import num_cell, render, table, text_cell
from dvrk_dart.model.joints import JOINT_NAMES

SHOWN_JOINTS = JOINT_NAMES[:3]


def uncertainty_section(folder: Path) -> tuple[str, str, list[Path]]:
    summary = json.loads((folder / "uncertainty.json").read_text())
    figures = sorted((folder / "figures").glob("band_*.png"))
    low, high = summary["band_quantiles"]
    rows = []
    for key, label in (("measured_inside_band_fraction", "measured samples inside the band (fraction)"),
                       ("rms_measured_outside_band", "RMS distance of the measured effort to the band"),
                       ("band_width_rms", "RMS width of the band"),
                       ("nominal_model_inside_band_fraction", "nominal identified model inside the band (fraction)")):
        rows.append([text_cell(label), *(num_cell(summary[key][JOINT_NAMES.index(j)], uncertainty=key, joint=j) for j in SHOWN_JOINTS)])
    band_table = table(["", *[f"{j} ({summary['effort_units'][JOINT_NAMES.index(j)]})" for j in SHOWN_JOINTS]], rows)
    body = render("sections/uncertainty.html", summary=summary, low=low, high=high, band_table=band_table, figures=figures)
    return ("Parameter uncertainty: the held-out replay of two", body, figures)
