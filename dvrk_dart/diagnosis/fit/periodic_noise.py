"""What the periodic layer's measured noise costs a fit, for the selection (`selection.Selector`).

In the periodic processing every period is a copy, so a time fold is no held-out data: a fold's noise is fitted in
the other folds. The selection's score then pays the noise each fitted parameter absorbs, twice (Mallows' Cp,
`optimism`), and a step must remove more than the noise of the directions its columns span (`beyond_noise`, a
chi-square test over the candidates that competed)."""

from __future__ import annotations

from typing import Callable

import numpy as np
from scipy.stats import chi2

from dvrk_dart.diagnosis.fit.design import Design, Fit, Grams, sse
from dvrk_dart.model.joints import N_JOINTS

#: periodic: a step's fit (and a payload's joints beyond a rival payload's) must remove more than the noise
#: of the directions its columns span, at this level divided over the candidates that competed
#: (`PeriodicNoise.beyond_noise`, `Selector._payload_joints_earned`)
BEYOND_NOISE_LEVEL = 0.05


class PeriodicNoise:
    """The noise accounting of one selection's training Grams (`train.noise` measured) and fit weights."""

    def __init__(self, design: Design, train: Grams, fit_w2: np.ndarray, fit_all: Callable[[list[int]], Fit]):
        self.design, self.train, self.fit_w2, self.fit_all = design, train, fit_w2, fit_all
        self._span: dict[int, np.ndarray] = {}
        self._absorbed_by: dict[tuple[int, ...], np.ndarray] = {}
        # the optimism of a linear column: 2 x the noise energy it absorbs, spread over the blocks and joints where
        # it lives (sum over them: x^T (W D) x / x^T W x)
        diag = np.einsum("bjpp->bjp", train.A)  # (b, 7, P)
        den = np.einsum("bjp,j->p", diag, fit_w2)
        share = np.einsum("bjp,bj,j->pbj", diag, train.noise, fit_w2)  # in train.s units
        self.noise_share = np.where(den[:, None, None] > 0, share / np.where(den > 0, den, 1.0)[:, None, None], 0.0)

    def optimism(self, chosen: list[int]) -> np.ndarray:
        """(n_blocks, 7) twice the noise energy the chosen effects' fitted
        parameters absorb: a linear effect's seen parameters, each the mean of
        its columns' share; a nonlinear effect, the noise its columns' span
        absorbs (the fit reaches about as far: a first-moment payload's tied
        inertia, small masses far out, took 2.7 to 4 times the noise its
        parameters' local directions absorb on joints carrying noise only)."""
        total = np.zeros_like(self.train.s)
        for i in chosen:
            sl, e = self.design.slices[i], self.design.effects[i]
            if not e.linear:
                total += 2.0 * self.span_absorbed(i)
                continue
            shares = self.noise_share[sl]
            live = [k for k in range(len(shares)) if shares[k].any()]
            if live:
                total += 2.0 * e.n_seen_parameters * shares[live].mean(0)
        return total

    def span_absorbed(self, i: int) -> np.ndarray:
        """(n_blocks, 7) the noise energy a weighted least-squares fit on effect i's columns absorbs, per block and joint
        (train.s units): noise_bj x its share of the span's directions."""
        return self.train.noise * self.span_directions(i)

    def span_directions(self, i: int) -> np.ndarray:
        """(n_blocks, 7) w2_j tr(G^+ A_bj), G = sum w2_j A_bj: the weighted hat matrix's trace (the directions effect
        i's columns span) split by block and joint; made once per effect (every candidate set it is in reads it)."""
        if i not in self._span:
            A = self.train.A[:, :, self.design.slices[i], self.design.slices[i]]
            G = np.einsum("bjpq,j->pq", A, self.fit_w2)
            # on unit columns: the trace is the same, and which near-collinear directions count is not set by the units
            scale = np.sqrt(np.diag(G))
            scale = np.where(scale > 0, scale, 1.0)
            inverse = np.linalg.pinv(G / np.outer(scale, scale), rcond=1e-10, hermitian=True) / np.outer(scale, scale)
            self._span[i] = self.fit_w2[None, :] * np.einsum("pq,bjqp->bj", inverse, A)
        return self._span[i]

    def beyond_noise(self, selected: list[int], added: list[int], competing: int) -> bool:
        """Whether the step's in-sample fit removes more than the noise of the directions its columns span, at
        BEYOND_NOISE_LEVEL over the candidates that competed (Cp charges one candidate's average catch; a time shift,
        the best of sixty, took 27 % of q3's noise with one direction)."""
        removed = self.absorbed(selected + added) - self.absorbed(selected)
        statistic, degrees = self.statistic(added, removed, list(range(N_JOINTS)))
        return bool(degrees == 0 or statistic >= chi2.isf(BEYOND_NOISE_LEVEL / max(competing, 1), degrees))

    def statistic(self, effects: list[int], removed: np.ndarray, joints: list[int]) -> tuple[float, float]:
        """(statistic, degrees): the energy `removed` (7,) on `joints` over the noise per direction there of the
        effects' columns, and the directions those columns span there (chi-square with those degrees when the
        residual there is noise)."""
        directions = sum(self.span_directions(i) for i in effects)[:, joints].sum(0)
        expected = sum(self.span_absorbed(i) for i in effects)[:, joints].sum(0)
        live = (directions > 0) & (expected > 0)
        return float(np.sum(removed[joints][live] * directions[live] / expected[live])), float(directions[live].sum())

    def absorbed(self, chosen: list[int]) -> np.ndarray:
        """(7,) the training residual energy the chosen effects' in-sample fit removes, per joint (made once per set)."""
        key = tuple(sorted(chosen))
        if key not in self._absorbed_by:
            fit = self.fit_all(list(key)) if key else None
            self._absorbed_by[key] = np.zeros(N_JOINTS) if fit is None else (
                self.train.s - sse(fit.beta, self.train.A, self.train.g, self.train.s)).sum(0)
        return self._absorbed_by[key]
