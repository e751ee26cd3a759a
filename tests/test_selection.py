"""The greedy selection on effects given by their columns alone (no arm): what its backward pass drops."""

from types import SimpleNamespace

import numpy as np

from dvrk_dart.diagnosis.effects.effect import Effect, Parameter
from dvrk_dart.diagnosis.fit.design import Design, Grams
from dvrk_dart.diagnosis.fit.selection import Selector
from dvrk_dart.model.joints import N_JOINTS

RATE_HZ = 100.0
SAMPLES = 3000  # 30 one-second blocks


class GivenColumns(Effect):
    """An effect whose (N, 7, 1) column is given."""

    kind = "given"
    parameters = (Parameter("k", "1"),)

    def __init__(self, name: str, column: np.ndarray):
        self.name, self.column = name, column
        self.joints = ("q1", "q2", "q3")

    def columns(self, features):
        return self.column

    def sim_contribution(self, p):
        return None


def _smooth(rng: np.random.Generator) -> np.ndarray:
    """A band-limited unit-RMS signal (a few cycles a block, as an excitation's efforts)."""
    t = np.arange(SAMPLES) / RATE_HZ
    x = sum(rng.normal() * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) for f in rng.uniform(0.2, 3.0, 8))
    return x / np.sqrt(np.mean(x ** 2))


def _on_joint(signal: np.ndarray, joint: int) -> np.ndarray:
    column = np.zeros((SAMPLES, N_JOINTS, 1))
    column[:, joint, 0] = signal
    return column


def test_a_first_pick_the_later_effects_stand_in_for_is_dropped():
    """Three joints each carry their own effect; a shared one-parameter effect correlates 0.6 with each of them, so
    alone it explains 0.36 of every joint (more than any joint's own effect, a third of the three) and comes first.
    Once the three are in it explains nothing: the backward pass drops it, and the step says so."""
    rng = np.random.default_rng(0)
    own = [_smooth(rng) for _ in range(3)]
    other = [_smooth(rng) for _ in range(3)]
    shared = sum(_on_joint(0.6 * own[j] + 0.8 * other[j], j) for j in range(3))
    effects = [GivenColumns("shared", shared)] + [GivenColumns(f"own_q{j + 1}", _on_joint(own[j], j)) for j in range(3)]
    residual = sum(_on_joint(own[j], j) for j in range(3))[:, :, 0] + 0.01 * rng.standard_normal((SAMPLES, N_JOINTS))
    design = Design(effects)
    grams = Grams.of_run(design, SimpleNamespace(sample_rate_hz=RATE_HZ), residual, folds=5, Phi=design.columns(None))
    w2 = np.r_[np.ones(3), np.zeros(N_JOINTS - 3)]
    selected, steps, _, current = Selector(design, grams, w2, folds=5).greedy(max_effects=6)
    assert steps[0]["effect"] == "shared" and steps[0]["accepted"]
    assert steps[0]["dropped_after"]["loss"] < 0.005
    assert sorted(effects[i].name for i in selected) == ["own_q1", "own_q2", "own_q3"]
    assert current.fraction > 0.99
