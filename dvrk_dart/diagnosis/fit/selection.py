"""Diagnosis of the sim-to-real gap: where the simulation departs from the real
robot, which unmodelled physical effect explains it, and how much of the gap
closes once the effect is put into the simulation, judged on held-out data.

Residual r = measured - simulated effort, per joint (with a baseline run of
the same trajectory and session but without the effect under study:
r = (measured - simulated) - (baseline measured - baseline simulated), which
cancels the day-to-day effects and isolates the withheld one).

Selection (`diagnose`):
- every candidate effect of `effects.candidate_effects` is a regressor
  Y(q, dq, ddq) beta(p) with physical bounds on p;
- the training residual is cut into blocks of BLOCK_DURATION_S (longer in a
  run of over MAX_BLOCKS_PER_RUN of them); per block and
  joint the Gram matrices Y^T Y, Y^T r, r^T r of all candidates are stored, so
  any fit and any held-out error is a small matrix computation;
- a fit minimises the weighted squared residual over the joints (weight
  1 / RMS of the joint's residual before, so that N and N·m and large and small
  joints count alike), with bounded least squares;
- the score of a set of effects is its explained fraction on held-out time
  segments (CV_FOLDS contiguous folds: fit on the others, score on the fold),
  with a block bootstrap over the held-out blocks for its uncertainty. In the
  periodic processing every period is a copy, so a fold's noise is fitted in
  the other folds: the score then also pays the noise each fitted parameter
  absorbs, twice (Mallows' Cp, from the periodic layer's measured noise; a
  nonlinear effect pays what its columns' span absorbs, as far as its fit
  reaches). The
  folds stay: with copies weighted twice against once they still test how the
  fit moves under model error, which noise alone does not show (measured: a
  pure Cp score let richer effects in that did not carry to the held-out
  trajectory, "two" J3 0.080 -> 0.113 N);
- greedy forward selection adds the effect with the best held-out score (or a
  simpler one, fewer parameters, not significantly worse and with 90 % of its
  gain) while the gain is at
  least MIN_HELDOUT_GAIN and positive with bootstrap confidence, refusing a
  candidate that makes a selected effect unstable across folds (collinear)
  unless that effect is then unneeded;
  at most one effect of a family is selected (a joint's friction with a sharp
  or a smooth reversal); a payload is chosen only if it beats, significantly,
  the offsets of the joints it moves fitted together (its static part), else
  those offsets are the step's choice; in the periodic processing a payload
  that moves joints a rival payload does not must earn them against their
  noise (a chi-square test), else the rival is the step's choice, and every
  step must remove more than the noise of the directions its columns span
  (the same test, over the candidates that competed for it,
  `periodic_noise.PeriodicNoise`);
- a backward pass then drops, the least missed first, every effect whose
  place the later ones took (the set without it loses less than
  MIN_HELDOUT_GAIN, or not with bootstrap confidence);
- payloads on links whose efforts are identical (a family, see
  `payload.equivalent_payload_links`) are one hypothesis over the union of
  their envelopes: the member kept is the one with the lowest penalised
  training cost, and the mass interval is profiled over the whole family;
  `holdout` runs are never used for the selection, only scored.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from dvrk_dart.diagnosis.fit.design import (
    Design,
    Fit,
    Fitter,
    Grams,
    sse,
    weighted_fraction,
)
from dvrk_dart.diagnosis.fit.periodic_noise import BEYOND_NOISE_LEVEL, PeriodicNoise
from dvrk_dart.diagnosis.effects.payload import PointPayload
from dvrk_dart.model.joints import JOINT_NAMES

#: contiguous folds of the held-out scoring: a fold of a 28 s run is ~1 base
#: period (5.6 s) of the excitation, so each fold holds a full trajectory cycle
CV_FOLDS = 5
#: bootstrap resamples of the held-out blocks (interval of explained fractions)
BOOTSTRAP_RESAMPLES = 400
BOOTSTRAP_SEED = 20190802
#: central interval reported for explained fractions
INTERVAL_QUANTILES = (0.05, 0.95)
#: an effect is added only if it explains at least this fraction more of the
#: held-out (weighted) squared residual ...
MIN_HELDOUT_GAIN = 0.005
#: ... and its gain is positive in all but this fraction of bootstrap resamples
GAIN_FAILURE_QUANTILE = 0.05
#: a simpler rival must also bring at least this share of the best candidate's
#: gain: "not significantly worse" alone let rivals in at a third of the best's
#: gain where the bootstrap over a few blocks is wide (an armature for a
#: payload, a payload for J3's stroke friction)
PARSIMONY_GAIN_SHARE = 0.9
#: an effect is not separable from the others when its fitted effort varies
#: from fold to fold by more than this fraction of its size (weighted norm);
#: a candidate that makes an already selected effect that unstable is refused
#: (e.g. a J2 stiffness trading off against a payload's lever arm)
STABILITY_LIMIT = 0.5


@dataclass
class CvResult:
    after: np.ndarray  # (n_blocks, 7) held-out squared residual per block
    fraction: float
    fold_params: list[dict[int, np.ndarray]]


class Selector:
    """Cross-validated scores, bootstrap intervals and greedy forward selection."""

    def __init__(self, design: Design, train: Grams, w2: np.ndarray, folds: int, fit_w2: np.ndarray | None = None):
        """w2: the joints' weights of the scores (explained fractions, bootstrap); fit_w2: the fits' (w2 if None)."""
        self.design, self.train, self.w2 = design, train, w2
        self.fit_w2 = w2 if fit_w2 is None else fit_w2
        self.fitter = Fitter(design)
        self.folds = sorted(set(train.fold.tolist()))
        Aw = np.einsum("bjpq,j->bpq", train.A, self.fit_w2)
        gw = np.einsum("bjp,j->bp", train.g, self.fit_w2)
        self.A_total, self.g_total = Aw.sum(0), gw.sum(0)
        sw = train.s @ self.fit_w2
        self.energy_total = float(sw.sum())
        self.energy_fold = {f: float(sw[train.fold == f].sum()) for f in self.folds}
        self.A_fold = {f: Aw[train.fold == f].sum(0) for f in self.folds}
        self.g_fold = {f: gw[train.fold == f].sum(0) for f in self.folds}
        rng = np.random.default_rng(BOOTSTRAP_SEED)
        n = len(train.s)
        self.resamples = rng.integers(0, n, size=(BOOTSTRAP_RESAMPLES, n))
        self._fitted: dict[tuple, Fit] = {}
        self.penalised = train.noise is not None
        self.noise = PeriodicNoise(design, train, self.fit_w2, self.fit_all) if self.penalised else None

    def fitting_by(self, fit_w2: np.ndarray) -> "Selector":
        """The same scores, the fits weighted by `fit_w2`."""
        return Selector(self.design, self.train, self.w2, len(self.folds), fit_w2)

    def fit_all(self, chosen, warm=None) -> Fit:
        """The effects `chosen` fitted on all training data; without a warm start, once per set and bounds (the
        report asks again for the fits the selection made; `mass_profile` narrows a payload's mass in place;
        callers read the Fit, never change it)."""
        if warm is not None:
            return self.fitter.fit(chosen, self.A_total, self.g_total, warm, self.energy_total)
        key = tuple((i, *((p.lower, p.upper) for p in self.design.effects[i].parameters)) for i in chosen)
        if key not in self._fitted:
            self._fitted[key] = self.fitter.fit(chosen, self.A_total, self.g_total, None, self.energy_total)
        return self._fitted[key]

    def cross_validate(self, chosen: list[int], warm: list[dict[int, np.ndarray]] | None = None) -> CvResult:
        after = self.train.s.copy()
        fold_params = []
        for k, f in enumerate(self.folds):
            if len(self.folds) == 1:  # no held-out fold: in-sample
                fit = self.fit_all(chosen, warm[k] if warm else None)
                after = sse(fit.beta, self.train.A, self.train.g, self.train.s)
                fold_params.append(fit.params)
                break
            fit = self.fitter.fit(chosen, self.A_total - self.A_fold[f], self.g_total - self.g_fold[f], warm[k] if warm else None,
                                  self.energy_total - self.energy_fold[f], linearize=warm is not None)
            held = self.train.fold == f
            # on every block, then the fold's: sse reads only the fitted columns of A, where
            # A[held] would copy every block's whole Gram matrix first (most of the selection's time)
            after[held] = sse(fit.beta, self.train.A, self.train.g, self.train.s)[held]
            fold_params.append(fit.params)
        if self.penalised:  # the folds' copies in the other folds: the noise fitted is not held out, its optimism added
            after = after + self.noise.optimism(chosen)
        return CvResult(after, weighted_fraction(after, self.train.s, self.w2), fold_params)

    def bootstrap_fractions(self, after: np.ndarray) -> np.ndarray:
        num = np.einsum("bj,j->b", after, self.w2)[self.resamples].sum(1)
        den = np.einsum("bj,j->b", self.train.s, self.w2)[self.resamples].sum(1)
        return 1.0 - num / den

    def interval(self, after: np.ndarray) -> list[float]:
        return np.quantile(self.bootstrap_fractions(after), INTERVAL_QUANTILES).tolist()

    def _index(self, name: str) -> int:
        return next(i for i, e in enumerate(self.design.effects) if e.name == name)

    def instability(self, effect: int, result: CvResult) -> float:
        """Fold-to-fold spread of an effect's fitted effort relative to its size."""
        sl = self.design.slices[effect]
        e = self.design.effects[effect]
        betas = np.array([e.coefficients(p[effect]) for p in result.fold_params if effect in p])
        if len(betas) < 2:
            return 0.0
        A = self.A_total[sl, sl]
        mean = betas.mean(0)
        size = float(mean @ A @ mean)
        spread = float(np.mean([(b - mean) @ A @ (b - mean) for b in betas]))
        return math.sqrt(spread / size) if size > 0 else 0.0

    def _stable(self, selected: list[int], candidate: int, trial: CvResult, current: CvResult) -> bool:
        """Whether no selected effect turns unstable with the candidate, but one the candidate makes unneeded (the
        backward pass drops it: an effect shared by three joints, first for 0.6 of each, in the way of the third
        joint's own)."""
        for i in selected:
            before = self.instability(i, current)
            if self.instability(i, trial) > max(STABILITY_LIMIT, before) and not self._unneeded(i, selected + [candidate], trial):
                return False
        return True

    def _unneeded(self, effect: int, chosen: list[int], trial: CvResult) -> bool:
        """Whether `chosen` without `effect` scores within MIN_HELDOUT_GAIN of `trial` (chosen's score)."""
        rest = [k for k in chosen if k != effect]
        without = self.cross_validate(rest, [{k: v for k, v in p.items() if k != effect} for p in trial.fold_params])
        return trial.fraction - without.fraction < MIN_HELDOUT_GAIN

    def _parsimonious(self, trials: dict[int, CvResult], current: CvResult) -> int:
        """The best-scoring candidate, unless one with fewer parameters is not
        significantly worse (bootstrap), brings PARSIMONY_GAIN_SHARE of its gain
        and is itself worth adding (gain at least MIN_HELDOUT_GAIN): then the simplest of those (an offset before a
        payload that mimics it over a small range of motion). A simpler rival
        below the bar must not stop the selection before a better candidate
        that clears it (a payload behind a 1-parameter effect that adds less)."""
        best = max(trials, key=lambda i: trials[i].fraction)
        best_boot = self.bootstrap_fractions(trials[best].after)
        n_par = lambda i: self.design.effects[i].n_seen_parameters
        rivals = []
        best_gain = trials[best].fraction - current.fraction
        for i, t in trials.items():
            gain = t.fraction - current.fraction
            if n_par(i) < n_par(best) and gain >= MIN_HELDOUT_GAIN and gain >= PARSIMONY_GAIN_SHARE * best_gain:
                worse = best_boot - self.bootstrap_fractions(t.after)
                if np.mean(worse <= 0.0) > GAIN_FAILURE_QUANTILE:
                    rivals.append(i)
        if not rivals:
            return best
        fewest = min(n_par(i) for i in rivals)
        return max((i for i in rivals if n_par(i) == fewest), key=lambda i: trials[i].fraction)

    def greedy(self, max_effects: int) -> tuple[list[int], list[dict], dict[int, CvResult], CvResult]:
        n = len(self.design.effects)
        individual: dict[int, CvResult] = {}
        selected: list[int] = []
        current = CvResult(self.train.s.copy(), 0.0, [{} for _ in self.folds])
        steps = []
        while len(selected) < min(max_effects, n):
            trials = {}
            families = {self.design.effects[i].selection_group for i in selected}
            for i in range(n):
                if i in selected or self.design.effects[i].selection_group in families or not getattr(self.design.effects[i], "candidate", True):
                    continue
                warm = [dict(p) for p in current.fold_params]
                trials[i] = self.cross_validate(selected + [i], warm)
                if not selected:
                    individual[i] = trials[i]
            self._last_trials = trials
            admissible = {i: t for i, t in trials.items() if self._stable(selected, i, t, current)}
            refused = [self.design.effects[i].name for i in trials if i not in admissible and trials[i].fraction > current.fraction]
            if not admissible:
                break
            scored_best = self._parsimonious(admissible, current)
            best = self._payload_joints_earned(selected, scored_best, admissible, current)
            added, trial, instead_of = [best], trials[best], None if best == scored_best else self.design.effects[scored_best].name
            rival = self._offset_rival(selected, best, families, current)
            if rival is not None:
                added, trial, instead_of = rival[0], rival[1], self.design.effects[best].name
            gain, gains, failure = self._gain(trial, current)
            beyond_noise = self._beyond_noise(selected, added, len(trials))
            if not _clears(gain, failure, beyond_noise):
                runner_up = self._significant_runner_up(admissible, current, set(added) | {best}, selected)
                if runner_up is not None:
                    instead_of = self.design.effects[best].name
                    added, trial, beyond_noise = [runner_up], trials[runner_up], True
                    gain, gains, failure = self._gain(trial, current)
            step = {
                "effect": " + ".join(self.design.effects[i].name for i in added),
                "effects": [self.design.effects[i].name for i in added],
                "instead_of": instead_of,
                "cross_validated_fraction": trial.fraction,
                "gain": gain,
                "gain_interval": np.quantile(gains, INTERVAL_QUANTILES).tolist(),
                "gain_not_positive_probability": failure,
                "beyond_noise": beyond_noise,
                "refused_as_not_separable": [n for n in refused if trials[self._index(n)].fraction > trials[best].fraction],
            }
            if not _clears(gain, failure, beyond_noise):
                step["accepted"] = False
                steps.append(step)
                break
            step["accepted"] = True
            steps.append(step)
            selected.extend(added)
            current = trial
        selected, current = self.prune(selected, current, steps)
        return selected, steps, individual, current

    def prune(self, selected: list[int], current: CvResult, steps: list[dict]) -> tuple[list[int], CvResult]:
        """The backward pass: an effect whose place the later ones took (left out, the set loses less than
        MIN_HELDOUT_GAIN, or not with bootstrap confidence) is dropped, the least missed first, until each one
        left is needed; its step says so. A first pick that stood in for several joints' effects at once (a time
        shift of 28 ms mimicking seven joints' viscous friction, 0.2 ms once they were in) is not named."""
        while len(selected) > 1:
            trials = {i: self.cross_validate([k for k in selected if k != i], [{k: v for k, v in p.items() if k != i} for p in current.fold_params])
                      for i in selected}
            losses = {i: self._gain(current, trial) for i, trial in trials.items()}
            least = min(selected, key=lambda i: losses[i][0])
            loss, _, failure = losses[least]
            if _clears(loss, failure, True):
                break
            name = self.design.effects[least].name
            step = next(s for s in steps if s["accepted"] and name in s["effects"])
            step["dropped_after"] = {"loss": loss, "loss_not_positive_probability": failure}
            selected = [k for k in selected if k != least]
            current = trials[least]
        return selected, current

    def _payload_joints_earned(self, selected: list[int], best: int, trials: dict[int, CvResult], current: CvResult) -> int:
        """Occam's rule for a payload's joints (periodic): a payload that moves joints a rival payload of another
        family does not (a parallelogram link against the yaw link) is kept only if its fit there is beyond their
        noise (`PeriodicNoise.statistic`, at BEYOND_NOISE_LEVEL over the candidates that competed: the step's best caught
        62 % of q2's noise in 3 of its 12 directions), else the best-scoring rival is the choice. Upstream: `best`."""
        effect = self.design.effects[best]
        if not self.penalised or effect.kind != "payload":
            return best
        joints = lambda i: {JOINT_NAMES.index(j) for j in self.design.effects[i].joints}
        payloads = [i for i in trials if self.design.effects[i].kind == "payload"]
        rivals = [i for i in payloads if self.design.effects[i].family != effect.family and joints(i) < joints(best)
                  and trials[i].fraction - current.fraction >= MIN_HELDOUT_GAIN]
        absorbed_by_best = self.noise.absorbed(selected + [best]) if rivals else None
        for rival in sorted(rivals, key=lambda i: -trials[i].fraction):
            extra = sorted(joints(best) - joints(rival))
            statistic, degrees = self.noise.statistic([best], absorbed_by_best - self.noise.absorbed(selected + [rival]), extra)
            if degrees > 0 and statistic < chi2.isf(BEYOND_NOISE_LEVEL / len(trials), degrees):
                return rival
        return best

    def _beyond_noise(self, selected: list[int], added: list[int], competing: int) -> bool:
        """Periodic: `PeriodicNoise.beyond_noise`; upstream (no noise measured): True."""
        return self.noise is None or self.noise.beyond_noise(selected, added, competing)

    def _gain(self, trial: CvResult, current: CvResult) -> tuple[float, np.ndarray, float]:
        """A step's gain, its bootstrap resamples and the share of them not positive."""
        gains = self.bootstrap_fractions(trial.after) - self.bootstrap_fractions(current.after)
        return trial.fraction - current.fraction, gains, float(np.mean(gains <= 0.0))

    def _significant_runner_up(self, trials: dict[int, CvResult], current: CvResult, tried: set[int], selected: list[int]) -> int | None:
        """The best-scoring candidate whose gain clears the bar, when the best
        scorer's does not: a candidate that fits more (a payload's eight
        parameters on a joint's noise) but not significantly must not stop
        the selection before one that explains a joint for certain (a
        one-joint load under a baseline's doubled noise)."""
        for i in sorted(trials, key=lambda i: -trials[i].fraction):
            if i in tried:
                continue
            gain, _, failure = self._gain(trials[i], current)
            if gain < MIN_HELDOUT_GAIN:
                return None
            if failure <= GAIN_FAILURE_QUANTILE and self._beyond_noise(selected, [i], len(trials)):
                return i
        return None

    def _offset_rival(self, selected: list[int], best: int, families: set, current: CvResult) -> tuple[list[int], CvResult] | None:
        """Occam's rule for a payload: its static part is an offset on every
        joint it moves; the payload is chosen only if it explains the held-out
        residual significantly better than those offsets fitted together
        (fewer parameters). Else the offsets are the step's choice (e.g. on
        trajectory 'one' a 0.6 kg "payload" on the pitch link pinned at its
        envelope boundary only mimicked the J1 and J2 offsets)."""
        effect = self.design.effects[best]
        if not isinstance(effect, PointPayload):
            return None
        by_name = {e.name: i for i, e in enumerate(self.design.effects)}
        rival = [by_name[f"offset_{j}"] for j in effect.joints if f"offset_{j}" in by_name]
        rival = [i for i in rival if i not in selected and self.design.effects[i].selection_group not in families]
        if not rival or sum(self.design.effects[i].n_parameters for i in rival) >= effect.n_parameters:
            return None
        trial = self.cross_validate(selected + rival, [dict(p) for p in current.fold_params])
        if trial.fraction <= current.fraction:
            return None
        payload_boot = self.bootstrap_fractions(self._last_trials[best].after) if best in self._last_trials else None
        if payload_boot is None:
            return None
        better = payload_boot - self.bootstrap_fractions(trial.after)
        if np.mean(better <= 0.0) > GAIN_FAILURE_QUANTILE:  # the payload is not significantly better
            return rival, trial
        return None


def _clears(gain: float, failure: float, beyond_noise: bool) -> bool:
    """Whether a step is taken: its gain at least MIN_HELDOUT_GAIN, positive with bootstrap confidence, beyond the noise."""
    return gain >= MIN_HELDOUT_GAIN and failure <= GAIN_FAILURE_QUANTILE and beyond_noise
