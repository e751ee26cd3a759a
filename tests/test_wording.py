"""One rule for the diagnosis's words (diagnosis/output/wording.py), the same in the
answer sentence, the page and diagnosis.json."""

import pytest

from dvrk_dart.diagnosis.output.answer import answer_sentence
from dvrk_dart.diagnosis.output.wording import explanation, words_for
from arms import PSM

JOINTS = ["q1", "q2", "q3", "q4", "q5", "q6", "q7"]


@pytest.mark.parametrize("share, words", [(None, "not explained"), (0.0, "not explained"), (0.19, "not explained"),
                                          (0.2, "partly explained"), (0.5, "partly explained"), (0.51, "mostly explained")])
def test_the_words_follow_the_share(share, words):
    assert words_for(share) == words


def _result(before, after, selected_joints):
    gap_before = {"train": before + [0.01] * 4, "holdout": None}
    gap_after = {"train": after + [0.01] * 4, "holdout": None}
    entries = [{"name": "friction_q2", "kind": "friction", "joints": selected_joints, "selected": True}]
    return {"gap_before": gap_before, "gap_after": gap_after, "selection": {"selected": ["friction_q2"]}, "effects": entries,
            "explanation": explanation(gap_before, gap_after, JOINTS, entries), "units": [PSM.effort_unit(j) for j in JOINTS]}


def test_only_the_joints_the_effects_act_on_count():
    """A friction on q2 that removes 1 % of J2's gap while J3's shrinks for another reason is not an explanation."""
    result = _result([0.3, 0.25, 0.6], [0.3, 0.2475, 0.1], ["q2"])
    assert result["explanation"]["joints"] == ["q2"] and result["explanation"]["removed_share"] == pytest.approx(0.01)
    assert result["explanation"]["words"] == "not explained"
    assert answer_sentence(result).startswith("The gap is not explained")


def test_the_answer_says_what_the_json_says():
    for after, words in (([0.3, 0.1, 0.6], "mostly explained"), ([0.3, 0.17, 0.6], "partly explained")):
        result = _result([0.3, 0.25, 0.6], after, ["q2"])
        assert result["explanation"]["words"] == words
        assert answer_sentence(result).startswith(f"The gap is {words} by")


def test_the_page_escapes_what_it_did_not_write():
    """Every value on diagnosis.html goes through the templates' autoescape: a run or effect name is text, not HTML."""
    from dvrk_dart.diagnosis.output.page import diagnosis_page

    result = _result([0.3, 0.25, 0.6], [0.1, 0.1, 0.1], ["q2"])
    result["effects"][0]["name"] = "friction_q2<script>alert(1)</script>"
    result["selection"]["selected"] = [result["effects"][0]["name"]]
    page = diagnosis_page(result, ["figures/a<b.png"], "diagnosis of <run>")
    assert "<script>" not in page and "&lt;script&gt;" in page and "diagnosis of &lt;run&gt;" in page
    assert page.count("<table") == 3  # the gaps, the ranked effects, their parameters: tables from the template
