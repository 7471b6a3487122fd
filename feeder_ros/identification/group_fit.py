"""Fitting one speed curve of a sweep: every candidate order of G(s), scored, the best kept.

A sweep (:class:`~feeder_ros.identification.sweep.SweepResult`) splits into curves, one per
(drive amplitude, part mass) (:class:`~feeder_ros.identification.sweep.SweepGroup`). Each curve
is fitted with the rational models of :attr:`FitSettings.orders`
(:func:`~feeder_ros.identification.rational_fit.compare_orders`: fit % on all points and on
held-out frequencies), and the best order is kept
(:func:`~feeder_ros.identification.rational_fit.best_order`). A curve that cannot be fitted
(too few usable frequencies, a failed fit) says why in :attr:`GroupFit.error`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from feeder_ros.identification.sweep import SweepDataError, SweepGroup, check_fit_data

if TYPE_CHECKING:
    from feeder_ros.identification.rational_fit import OrderScore

__all__ = ["DEFAULT_FOLDS", "FitSettings", "GroupFit", "fit_group"]

#: hold-out folds over frequency (interleaved) when orders are compared
DEFAULT_FOLDS = 5


@dataclass(frozen=True)
class FitSettings:
    """Candidate orders ``(zeros, poles)``, the speed below which a point is left out [m/s],
    and the hold-out folds."""

    orders: tuple[tuple[int, int], ...]
    min_speed_mps: float = 0.0
    folds: int = DEFAULT_FOLDS


@dataclass
class GroupFit:
    """The outcome for one (amplitude, mass) curve: the chosen order's scores, or why not."""

    group: SweepGroup
    scores: list[OrderScore] = field(default_factory=list)
    best: OrderScore | None = None
    peak_hz: float = math.nan
    left_out: list[str] = field(default_factory=list)
    error: str = ""

    @property
    def key(self) -> tuple[float, float]:
        return (self.group.amplitude_percent, self.group.part_mass_kg)


def fit_group(group: SweepGroup, settings: FitSettings) -> GroupFit:
    """Fit every order of ``settings`` that the curve's distinct frequencies can support (the
    others are listed in ``left_out``) and keep the best."""
    # imported here: ``feeder --help`` loads every sub-command's module, and this one pulls scipy
    from feeder_ros.identification.rational_fit import (
        IdentificationError,
        best_order,
        compare_orders,
        min_distinct_frequencies,
    )

    def need(zeros: int, poles: int) -> int:  # the hold-out scheme of compare_orders decides
        return min_distinct_frequencies(zeros, poles, settings.folds)

    outcome = GroupFit(group)
    try:
        check_fit_data(
            group.frequency_hz,
            group.speed_mps,
            min(need(z, p) for z, p in settings.orders),
            what=group.label,
        )
    except SweepDataError as error:
        outcome.error = str(error)
        return outcome
    distinct = len(set(group.frequency_hz.tolist()))
    orders = []
    for zeros, poles in settings.orders:
        needed = need(zeros, poles)
        if distinct < needed:
            outcome.left_out.append(
                f"order {zeros}/{poles} needs {needed} frequencies for the hold-out check, "
                f"{distinct} usable"
            )
        else:
            orders.append((zeros, poles))
    try:
        outcome.scores = compare_orders(
            group.frequency_hz, group.speed_mps, group.amplitude_n, orders, folds=settings.folds
        )
        outcome.best = best_order(outcome.scores)
        lo, hi = float(group.frequency_hz.min()), float(group.frequency_hz.max())
        outcome.peak_hz = outcome.best.fit.model.peak_frequency_hz(lo, hi)
    except IdentificationError as error:
        outcome.error = f"{group.label}: {error}"
    return outcome
