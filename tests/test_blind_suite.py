"""The blind effect suite's fixed subset (make validate runs all of it, both
processings, without and with a baseline): one case per effect family, each
in one variant, on two periods of "one" (two cases on the 2018 arm's design,
two on the half-speed motion of the 105 g run, three on another noise draw) made in DART with the effect
as physics and the measured noise. The top finding must be the injected class
on its joint, and the joint's gap after within 1.5x what the true physics
leaves (the issue's tolerance, not the project's)."""

import tomllib

import pytest

from dvrk_dart.diagnosis.checks.blind_suite import validate_blind_suite
from dvrk_dart.diagnosis.checks.validation import WITHHELD_FILE
from arms import PSM_ARM

#: (case, processing, with a baseline): one per family of the library
SUBSET = [("coulomb_q2", "upstream", True), ("offset_q1", "upstream", False), ("torsion_spring_q4", "periodic", False),
          ("motor_inertia_q1", "periodic", False), ("payload_counterweight", "periodic", True),
          # periodic, with a baseline: read as a carriage payload before the score paid the noise a payload's ten
          # parameters fit (selection.py, Mallows' Cp)
          ("offset_q1", "periodic", True),
          # the pitch-angle load on J3: claimed by an offset of q3 before the library held it
          ("pitch_load_q3", "periodic", False),
          # a carriage payload 0.3 m from the carriage's origin: read on the tool roll link while a payload's
          # second moment was left out (first_moment.py: now tied to its mass and first moment)
          ("payload_insertion", "periodic", True),
          # an arm lighter on J3 than identified: no candidate took mass away before a link's own mass was one
          ("lighter_carriage", "upstream", False),
          # every effort read 8 % high (asked for with --effort-scale): seven small effects were named before a scale was one
          ("effort_scale", "periodic", True),
          # efforts read 10 ms late, against a baseline: the sensor's path (the column's: test_measurement_effects.py)
          ("time_shift", "upstream", True)]
#: on another excitation design: the 2018 arm's, joints 1..3 logged, the wrist held (its runs write q1..q3 only)
OTHER_DESIGN = [("stroke_friction_q3", "periodic", True),
                # named on tool_roll, the injected group not named, while the held wrist moves the tool with the carriage
                ("payload_insertion", "upstream", True)]
#: the half-speed motion of the 105 g run (100 Hz, 6 harmonics in the band): a carriage payload of 4 g at about 1 m,
#: nearly all tied inertia, took 45-54 % of q2's and q3's noise while the score counted its parameters' local directions;
#: a yaw payload read on the parallelogram's intermediate link, whose fit took 62 % of q2's noise (3 of its 12
#: directions) and won on it, before a payload had to earn the joints a rival payload does not move
HALF_SPEED = [("offset_q1", "periodic", True), ("payload_yaw", "periodic", True)]
#: another noise draw (the suite's seed + 1), the parallelogram payload with a baseline. On "one" a time shift took 27 %
#: of q3's noise with one direction and bent the payload's fit (q2 at 3.4x) before a step had to remove more than the
#: noise of its directions; at half speed a counterweight "payload" took 64 % of q3's noise with 4 (q2 at 13x) before
#: a payload's joints were tested over all the step's candidates
OTHER_NOISE = [("payload_parallelogram", "periodic", True, "one"), ("payload_parallelogram", "periodic", True, "one-105g-half"),
               # a tool payload on the 2018 design: its off-axis first moment took q3's noise, which the gap's weights let pull
               # what q2 pins (q2 at 1.9x), before runs minus their baseline were refitted with the weights of what is left
               ("payload_tool", "periodic", True, "2018-test1")]
CASES = ([(*c, "one", 0) for c in SUBSET] + [(*c, "2018-test1", 0) for c in OTHER_DESIGN] + [(*c, "one-105g-half", 0) for c in HALF_SPEED]
         + [(*c, 1) for c in OTHER_NOISE])


@pytest.mark.parametrize("case, processing, baseline, run, seed_offset", CASES,
                         ids=[f"{c}-{p}-{'baseline' if b else 'alone'}-{r}{f'-seed+{s}' if s else ''}" for c, p, b, r, s in CASES])
def test_the_injected_effect_is_found_blind(case, processing, baseline, run, seed_offset, tmp_path):
    spec = {**tomllib.loads(WITHHELD_FILE.read_text())["blind_suite"], "subset": [case], "processings": [processing],
            "baselines": [baseline], "run": run, "seed_offset": seed_offset}
    summary, _ = validate_blind_suite(PSM_ARM, spec, tmp_path)
    (outcome,) = summary["cases"]
    assert outcome["named"], outcome
    assert outcome["gap_after"] <= 1.5 * outcome["floor"], outcome
