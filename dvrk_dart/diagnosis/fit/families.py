"""A payload family (links the efforts cannot tell apart) as one hypothesis: which member the selection keeps."""

from __future__ import annotations

import numpy as np

from dvrk_dart.diagnosis.effects.payload import PointPayload
from dvrk_dart.diagnosis.fit.design import PAYLOAD_MASS_PRIOR_PER_KG2, Fit
from dvrk_dart.diagnosis.fit.selection import CvResult, Selector


def penalised_cost(selector: Selector, chosen: list[int], fit: Fit) -> float:
    """Weighted training squared residual (up to a constant) plus the payloads' Occam prior."""
    masses = [fit.params[i][0] for i in chosen if isinstance(selector.design.effects[i], PointPayload)]
    prior = PAYLOAD_MASS_PRIOR_PER_KG2 * selector.energy_total
    A, g = selector.A_total, selector.g_total
    return float(fit.beta @ A @ fit.beta - 2 * fit.beta @ g + prior * np.sum(np.square(masses)))


def best_fit(selector: Selector, chosen: list[int], cv: CvResult | None = None) -> Fit:
    """Fit on all training data from the effects' own starting points and from
    the folds' mean parameters; keep the better (nonlinear fits have local minima)."""
    candidates = [selector.fit_all(chosen)]
    folds = [p for p in cv.fold_params if all(i in p for i in chosen)] if cv is not None else []
    if folds and chosen:
        warm = {i: np.mean([p[i] for p in folds], axis=0) for i in chosen}
        candidates.append(selector.fit_all(chosen, warm))
    return min(candidates, key=lambda fit: penalised_cost(selector, chosen, fit))


def family_members(selector: Selector, payload: int) -> list[int]:
    family = selector.design.effects[payload].family
    return [j for j, e in enumerate(selector.design.effects) if isinstance(e, PointPayload) and e.family == family]


def swap(chosen: list[int], old: int, new: int) -> list[int]:
    return [new if i == old else i for i in chosen]


def choose_within_families(selector: Selector, selected: list[int], cv: CvResult) -> tuple[list[int], Fit, CvResult]:
    """A payload family (links the efforts cannot tell apart) is one hypothesis
    over the union of its links' envelopes: its member is the one with the
    lowest penalised cost, the Occam prior deciding as it does within one link,
    not the held-out score, whose differences among members are noise."""
    final, swapped = best_fit(selector, selected, cv), False
    for payload in [i for i in selected if isinstance(selector.design.effects[i], PointPayload)]:
        for member in family_members(selector, payload):
            if member in selected:
                continue
            trial = swap(selected, payload, member)
            fit = best_fit(selector, trial)
            if penalised_cost(selector, trial, fit) < penalised_cost(selector, selected, final):
                selected, final, payload, swapped = trial, fit, member, True
    return selected, final, (selector.cross_validate(selected) if swapped else cv)
