"""Rational fit of a speed sweep (Eqs. 22-23 for magnitudes): known transfer functions are
recovered, over-fitting loses on held-out frequencies, and bad input is refused by name."""

from __future__ import annotations

import math

import numpy as np
import pytest

from feeder_ros.identification.rational_fit import (
    FREQUENCY_RESOLUTION_HZ,
    IdentificationError,
    RationalModel,
    best_order,
    compare_orders,
    distinct_frequencies,
    fit_percent,
    fit_rational,
    min_distinct_frequencies,
)

# A resonance near 47 Hz like the paper's Fig. 9/10: one real zero (30 Hz), a pole pair with
# damping ratio 0.08; swept 38-58 Hz in 0.5 Hz steps at 41 N (the paper's 41 % of 100 N).
OMEGA0 = 2.0 * math.pi * 47.0
ZETA = 0.08
POLE = complex(-ZETA * OMEGA0, OMEGA0 * math.sqrt(1.0 - ZETA**2))
ZERO = -2.0 * math.pi * 30.0
TRUE = RationalModel(0.05, (ZERO,), (POLE, POLE.conjugate()))
FREQUENCIES = np.linspace(38.0, 58.0, 41)
AMPLITUDE_N = 41.0
SPEEDS = TRUE.magnitude(FREQUENCIES) * AMPLITUDE_N  # about 17-51 mm/s


def noisy(seed: int, relative: float = 0.02) -> np.ndarray:
    """The true speeds with multiplicative Gaussian noise (seeded)."""
    rng = np.random.default_rng(seed)
    return SPEEDS * (1.0 + relative * rng.standard_normal(SPEEDS.size))


def upper_pole(model: RationalModel) -> complex:
    return max(model.poles, key=lambda p: p.imag)


def assert_roots_close(
    found: tuple[complex, ...], expected: tuple[complex, ...], rtol: float
) -> None:
    def key(root: complex) -> tuple[float, float]:
        return (round(root.real, 6), root.imag)

    assert len(found) == len(expected)
    for a, b in zip(sorted(found, key=key), sorted(expected, key=key), strict=True):
        assert abs(a - b) <= rtol * abs(b), (a, b)


# ------------------------------------------------------------------------------ fit_percent


def test_fit_percent_matches_a_hand_computation() -> None:
    # ||y - yhat|| = 1, ||y - mean(y)|| = sqrt(2.25 + 0.25 + 0.25 + 2.25) = sqrt(5)
    assert fit_percent([1, 2, 3, 4], [1, 2, 3, 5]) == pytest.approx(100 * (1 - 1 / math.sqrt(5)))
    assert fit_percent([1, 2, 3, 4], [1, 2, 3, 4]) == 100.0
    assert fit_percent([1, 2, 3, 4], [2.5] * 4) == pytest.approx(0.0)  # the mean: 0 %
    assert fit_percent([1, 2, 3, 4], [4, 3, 2, 1]) < 0.0  # worse than the mean


def test_fit_percent_refuses_what_it_cannot_score() -> None:
    with pytest.raises(IdentificationError, match=r"all measured values equal 2\.0"):
        fit_percent([2.0, 2.0], [1.0, 3.0])
    with pytest.raises(IdentificationError, match="measured has 3 values but predicted has 2"):
        fit_percent([1, 2, 3], [1, 2])
    with pytest.raises(IdentificationError, match=r"predicted\[1\] = nan"):
        fit_percent([1, 2, 3], [1, math.nan, 3])


# ------------------------------------------------------------------------------ the model


def test_response_and_peak_against_closed_forms() -> None:
    model = RationalModel(2.0, (-1.0,), (-3.0,))
    f = 0.7
    s = 2j * math.pi * f
    assert model.response(f) == pytest.approx(2.0 * (s + 1.0) / (s + 3.0))
    assert model.order == (1, 1)
    # 1 / (s^2 + 2 zeta w0 s + w0^2) peaks at w0 sqrt(1 - 2 zeta^2)
    resonance = RationalModel(1.0, (), (POLE, POLE.conjugate()))
    expected_hz = OMEGA0 * math.sqrt(1.0 - 2.0 * ZETA**2) / (2.0 * math.pi)
    assert resonance.peak_frequency_hz(38.0, 58.0) == pytest.approx(expected_hz, abs=1e-6)
    # a band above the peak: the maximum is at its lower edge
    assert resonance.peak_frequency_hz(50.0, 58.0) == pytest.approx(50.0, abs=1e-6)
    with pytest.raises(IdentificationError, match=r"low_hz=58 \.\. high_hz=38"):
        resonance.peak_frequency_hz(58.0, 38.0)


def test_model_dict_round_trip_and_refusals() -> None:
    data = TRUE.to_dict()
    assert data["zeros"] == [[ZERO, 0.0]]
    assert data["poles"] == [[POLE.real, POLE.imag], [POLE.real, -POLE.imag]]
    assert RationalModel.from_dict(data) == TRUE
    with pytest.raises(IdentificationError, match=r"missing field\(s\) gain"):
        RationalModel.from_dict({"zeros": [], "poles": []})
    with pytest.raises(IdentificationError, match=r"poles\[0\] = \(2\+0j\) is not stable"):
        RationalModel.from_dict({"gain": 1.0, "zeros": [], "poles": [[2.0, 0.0]]})
    with pytest.raises(IdentificationError, match=r"gain=nan is not finite"):
        RationalModel.from_dict({"gain": math.nan, "zeros": [], "poles": [[-1.0, 0.0]]})
    with pytest.raises(IdentificationError, match=r"poles\[0\] = \(-1\+2j\) has no complex-conj"):
        RationalModel.from_dict({"gain": 1.0, "zeros": [], "poles": [[-1.0, 2.0]]})
    with pytest.raises(IdentificationError, match=r"zeros\[0\]=\[1\.0\] is not an \[re, im\]"):
        RationalModel.from_dict({"gain": 1.0, "zeros": [[1.0]], "poles": [[-1.0, 0.0]]})
    with pytest.raises(IdentificationError, match="1 zeros > 0 poles"):
        RationalModel(1.0, (-1.0,), ())


# ------------------------------------------------------------------------------ recovery


@pytest.mark.parametrize(
    "true",
    [
        TRUE,
        RationalModel(50.0, (ZERO,), (POLE, POLE.conjugate(), -2.0 * math.pi * 80.0)),
        RationalModel(50.0, (), (POLE, POLE.conjugate())),
    ],
    ids=["1z2p", "1z3p", "0z2p"],
)
def test_noise_free_data_is_fitted_exactly(true: RationalModel) -> None:
    speeds = true.magnitude(FREQUENCIES) * AMPLITUDE_N
    result = fit_rational(FREQUENCIES, speeds, AMPLITUDE_N, *true.order)
    assert result.fit_percent > 99.9999
    assert result.residual_rms_mps < 1e-9 * speeds.max()
    assert_roots_close(result.model.poles, true.poles, rtol=1e-6)
    assert_roots_close(result.model.zeros, true.zeros, rtol=1e-6)
    assert result.model.gain == pytest.approx(true.gain, rel=1e-6)
    assert (result.zeros, result.poles) == true.order


def test_noisy_sweep_recovers_poles_zero_and_peak() -> None:
    measured = noisy(seed=3)
    result = fit_rational(FREQUENCIES, measured, AMPLITUDE_N, 1, 2)
    assert result.fit_percent > 90.0
    pole = upper_pole(result.model)
    # over 12 seeds the pole moved by at most 0.3 % and its real part by 2 %; the real zero at
    # 30 Hz lies below the band and only tilts it, so it is weakly determined (within 30 %)
    assert abs(pole - POLE) < 0.01 * abs(POLE)
    assert pole.real == pytest.approx(POLE.real, rel=0.05)
    assert result.model.zeros[0].real == pytest.approx(ZERO, rel=0.4)
    assert all(p.real < 0 for p in result.model.poles)
    true_peak = TRUE.peak_frequency_hz(38.0, 58.0)
    assert result.model.peak_frequency_hz(38.0, 58.0) == pytest.approx(true_peak, abs=0.25)
    # the model is closer to the truth than the measurements are
    model_error = np.sqrt(np.mean((result.predicted_speed_mps - SPEEDS) ** 2))
    noise = np.sqrt(np.mean((measured - SPEEDS) ** 2))
    assert model_error < 0.5 * noise
    assert result.residual_rms_mps == pytest.approx(
        np.sqrt(np.mean((measured - result.predicted_speed_mps) ** 2))
    )


def test_a_zero_in_the_right_half_plane_is_reported_minimum_phase() -> None:
    # |j w - z| = |j w + z| for real z: the magnitudes cannot tell the two apart
    mirrored = RationalModel(TRUE.gain, (-ZERO,), TRUE.poles)
    np.testing.assert_allclose(mirrored.magnitude(FREQUENCIES), TRUE.magnitude(FREQUENCIES))
    speeds = mirrored.magnitude(FREQUENCIES) * AMPLITUDE_N
    result = fit_rational(FREQUENCIES, speeds, AMPLITUDE_N, 1, 2)
    assert result.model.zeros[0] == pytest.approx(ZERO, rel=1e-6)


def test_repeated_runs_fit_like_their_mean() -> None:
    # sum_r (v_kr - m_k)^2 = R sum_k (mean_k - m_k)^2 + const: the same minimiser
    runs = np.stack([noisy(seed) for seed in (10, 11, 12)])
    repeated = fit_rational(np.tile(FREQUENCIES, 3), runs.ravel(), AMPLITUDE_N, 1, 2)
    averaged = fit_rational(FREQUENCIES, runs.mean(axis=0), AMPLITUDE_N, 1, 2)
    assert_roots_close(repeated.model.poles, averaged.model.poles, rtol=1e-5)
    assert repeated.model.gain == pytest.approx(averaged.model.gain, rel=1e-5)
    assert repeated.frequency_hz.size == 3 * FREQUENCIES.size


def test_zero_weight_removes_an_outlier() -> None:
    speeds = SPEEDS.copy()
    speeds[20] *= 3.0
    weights = np.ones_like(speeds)
    weights[20] = 0.0
    result = fit_rational(FREQUENCIES, speeds, AMPLITUDE_N, 1, 2, weights)
    assert result.fit_percent > 99.9999  # scored on the points that count
    assert_roots_close(result.model.poles, TRUE.poles, rtol=1e-6)
    unweighted = fit_rational(FREQUENCIES, speeds, AMPLITUDE_N, 1, 2)
    assert unweighted.fit_percent < 90.0


def test_negative_speeds_are_accepted_but_not_followed() -> None:
    speeds = SPEEDS - 0.03  # the part runs backwards away from the resonance
    assert np.any(speeds < 0.0)
    result = fit_rational(FREQUENCIES, speeds, AMPLITUDE_N, 1, 2)
    assert np.all(result.predicted_speed_mps >= 0.0)  # |G| A cannot go below zero ...
    assert result.fit_percent < 60.0  # ... so such a sweep just fits badly
    assert all(p.real < 0 for p in result.model.poles)


def test_fit_is_deterministic() -> None:
    first = fit_rational(FREQUENCIES, noisy(seed=5), AMPLITUDE_N, 1, 3)
    second = fit_rational(FREQUENCIES, noisy(seed=5), AMPLITUDE_N, 1, 3)
    assert first.model == second.model


# ------------------------------------------------------------------------------ order choice


def test_holdout_prefers_the_true_order_over_a_much_higher_one() -> None:
    orders = [(0, 2), (1, 2), (1, 3), (3, 6)]
    scores = compare_orders(FREQUENCIES, noisy(seed=1), AMPLITUDE_N, orders)
    by_order = {(s.zeros, s.poles): s for s in scores}
    assert [(s.zeros, s.poles) for s in scores] == orders
    assert by_order[(3, 6)].parameters == 10
    high, true = by_order[(3, 6)], by_order[(1, 2)]
    # on the data it was fitted to, the high order looks better ...
    assert high.fit_percent > true.fit_percent + 1.0
    # ... on held-out frequencies it is worse, and the choice is the true order
    assert high.holdout_fit_percent < true.holdout_fit_percent
    assert true.holdout_fit_percent > by_order[(0, 2)].holdout_fit_percent + 2.0
    chosen = best_order(scores)
    assert (chosen.zeros, chosen.poles) == (1, 2)
    assert chosen.fit.fit_percent == chosen.fit_percent > 90.0


def test_best_order_breaks_ties_towards_fewer_parameters() -> None:
    scores = compare_orders(FREQUENCIES, SPEEDS, AMPLITUDE_N, [(1, 3), (1, 2)])
    # both describe noise-free 1z2p data exactly: a tie, which the simpler one wins
    assert all(s.holdout_fit_percent > 99.99 for s in scores)
    assert (best_order(scores).zeros, best_order(scores).poles) == (1, 2)
    assert best_order(scores, tolerance_percent=0.0).holdout_fit_percent == max(
        s.holdout_fit_percent for s in scores
    )
    with pytest.raises(IdentificationError, match="no order scores"):
        best_order([])


def test_frequencies_within_the_resolution_are_one() -> None:
    """Points closer than FREQUENCY_RESOLUTION_HZ are repeats of one setting: they share a fold
    of the hold-out check and count once towards the order's needs."""
    f = np.array([45.0, 40.0, 40.0 + 1e-9, 50.0, 45.0 + 4e-7, 40.0 + 2e-6])
    distinct, inverse = distinct_frequencies(f)
    np.testing.assert_array_equal(distinct, [40.0, 40.0 + 2e-6, 45.0, 50.0])
    np.testing.assert_array_equal(inverse, [2, 0, 0, 3, 2, 1])
    assert FREQUENCY_RESOLUTION_HZ == 1e-6
    needed = min_distinct_frequencies(0, 1)
    spread = np.linspace(40.0, 50.0, needed)
    speeds = RationalModel(1.0, (), (-2.0 * math.pi * 45.0,)).magnitude(spread)
    nearly = spread.copy()
    nearly[1] = nearly[0] + 1e-10  # five points, four frequencies
    with pytest.raises(IdentificationError, match=r"needs >= 5 distinct frequencies.*got 4"):
        compare_orders(nearly, speeds, 1.0, [(0, 1)])


def test_min_distinct_frequencies_is_what_compare_orders_needs() -> None:
    needed = min_distinct_frequencies(0, 1)  # 3 parameters kept in every training set
    assert needed == 5
    f = np.linspace(40.0, 50.0, needed)
    speeds = RationalModel(1.0, (), (-2.0 * math.pi * 45.0,)).magnitude(f)
    assert len(compare_orders(f, speeds, 1.0, [(0, 1)])) == 1
    with pytest.raises(IdentificationError, match=r"needs >= 5 distinct frequencies.*got 4"):
        compare_orders(f[:-1], speeds[:-1], 1.0, [(0, 1)])


# ------------------------------------------------------------------------------ refusals

F = [40.0, 45.0, 50.0, 55.0]
V = [0.01, 0.03, 0.02, 0.01]


@pytest.mark.parametrize(
    ("frequency", "speed", "amplitude", "order", "message"),
    [
        ([40.0, math.nan, 50.0, 55.0], V, 1.0, (0, 1), r"frequency_hz\[1\] = nan is not finite"),
        (F, [0.01, 0.03, math.inf, 0.01], 1.0, (0, 1), r"speed_mps\[2\] = inf is not finite"),
        (F, V, 1.0, (1, 3), r"5 free parameters .* needs >= 6 distinct frequencies; got 4"),
        ([45.0] * 4, V, 1.0, (0, 0), r"only one distinct frequency \(45 Hz; frequencies closer"),
        # 1e-12 Hz apart: repeats of one setting, not a frequency response
        ([20.0 + k * 1e-12 for k in range(4)], V, 1.0, (0, 1), r"only one distinct frequency"),
        ([40.0, 40.0 + 1e-9, 50.0, 55.0], V, 1.0, (1, 1), r"needs >= 4 distinct.*; got 3"),
        ([40.0, 0.0, 50.0, 55.0], V, 1.0, (0, 1), r"frequency_hz\[1\] = 0\.0 must be > 0"),
        ([40.0, -5.0, 50.0, 55.0], V, 1.0, (0, 1), r"frequency_hz\[1\] = -5\.0 must be > 0"),
        (F, V[:3], 1.0, (0, 1), "frequency_hz has 4 values but speed_mps has 3"),
        (F, V, 1.0, (2, 1), "zeros=2 > poles=1"),
        (F, V, 1.0, (-1, 1), "zeros=-1 must be >= 0"),
        (F, V, 1.0, (0, -2), "poles=-2 must be >= 0"),
        (F, V, 0.0, (0, 1), r"amplitude_n=0\.0 must be > 0"),
        (F, V, -3.0, (0, 1), r"amplitude_n=-3\.0 must be > 0"),
        (F, V, math.nan, (0, 1), "amplitude_n=nan is not finite"),
        (F, [0.02] * 4, 1.0, (0, 1), r"every measured speed equals 0\.02"),
    ],
)
def test_fit_refuses_bad_input_naming_the_value(
    frequency: list[float],
    speed: list[float],
    amplitude: float,
    order: tuple[int, int],
    message: str,
) -> None:
    with pytest.raises(IdentificationError, match=message):
        fit_rational(frequency, speed, amplitude, *order)


@pytest.mark.parametrize(
    ("weights", "message"),
    [
        ([1.0, 1.0, 1.0], "weights has 3 values but frequency_hz has 4"),
        ([1.0, -0.5, 1.0, 1.0], r"weights\[1\] = -0\.5 must be >= 0"),
        ([1.0, 1.0, math.nan, 1.0], r"weights\[2\] = nan is not finite"),
        ([0.0] * 4, "weights are all zero"),
        ([1.0, 1.0, 0.0, 0.0], r"needs >= 3 distinct frequencies; got 2"),
    ],
)
def test_fit_refuses_bad_weights(weights: list[float], message: str) -> None:
    with pytest.raises(IdentificationError, match=message):
        fit_rational(F, V, 1.0, 0, 1, weights)


def test_compare_orders_refuses_bad_settings() -> None:
    with pytest.raises(IdentificationError, match="orders is empty"):
        compare_orders(FREQUENCIES, SPEEDS, AMPLITUDE_N, [])
    with pytest.raises(IdentificationError, match="folds=1 must be an integer >= 2"):
        compare_orders(FREQUENCIES, SPEEDS, AMPLITUDE_N, [(0, 1)], folds=1)
    with pytest.raises(IdentificationError, match="zeros=3 > poles=2"):
        compare_orders(FREQUENCIES, SPEEDS, AMPLITUDE_N, [(0, 1), (3, 2)])
