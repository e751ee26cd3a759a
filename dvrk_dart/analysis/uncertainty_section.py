"""The report's section on parameter uncertainty: the band of simulated
efforts over the parameter samples, the measured efforts in it, per joint."""

from __future__ import annotations

import json
from pathlib import Path

from dvrk_dart.io.html import _e, num_cell, table, text_cell
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
        rows.append("<tr>" + text_cell(label) + "".join(
            num_cell(summary[key][JOINT_NAMES.index(j)], uncertainty=key, joint=j) for j in SHOWN_JOINTS) + "</tr>")
    config = summary["config"]
    body = [
        f"<p>Is the measured effort already inside what the identified parameters' uncertainty allows? "
        f"{summary['samples_replayed']} parameter sets ({_e(summary['parameters'])}; {summary['projected_bodies']} body samples "
        f"projected onto physical consistency) replayed in DART on <code>{_e(config['measured'])}</code> "
        f"({_e(config['dynamics'])} arm, first {config['duration_s']} s). The band holds {low:.0%}-{high:.0%} of the simulated efforts; "
        "the distance of the measured effort to it is the part of the gap that no parameter set within the uncertainty explains.</p>",
        table(["", *[f"{j} ({summary['effort_units'][JOINT_NAMES.index(j)]})" for j in SHOWN_JOINTS]], rows),
        *[f"<figure><img src='figures/extra/{_e(p.name)}' alt='{_e(p.stem)}'><figcaption>{_e(p.stem)}: measured efforts over the "
          "parameter band</figcaption></figure>" for p in figures],
    ]
    return ("Parameter uncertainty: the held-out replay of two", "\n".join(body), figures)
