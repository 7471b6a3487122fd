"""Long runs drawn legibly: the min-max envelope of a long series and the parts' mean speed over
spans of the run (the helpers behind ``feeder sim --plot``), checked on series with known
answers, and the parts figure of a long simulated run."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from feeder_ros.figures import envelope
from feeder_ros.physics.case_study import plot_result, window_speeds
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import PartSpec, simulate


def test_the_envelope_keeps_each_spans_extremes_and_skips_parts_that_left() -> None:
    t = np.arange(60_000) / 1000.0  # a minute at 1 kHz
    ramp = 0.002 * t  # a part moving 2 mm/s, gone after 45 s
    y = np.stack([np.sin(2 * np.pi * 30.0 * t), np.where(t < 45.0, ramp, np.nan)], axis=1)
    middle, lowest, highest = envelope(t, y, bins=600)
    assert middle.size == 600
    assert middle[0] == pytest.approx(0.05, abs=1e-3)
    np.testing.assert_allclose(lowest[:, 0], -1.0, atol=1e-3)  # every 0.1 s holds 3 periods
    np.testing.assert_allclose(highest[:, 0], 1.0, atol=1e-3)
    span = slice(100, 101)  # 10.0 .. 10.1 s
    assert lowest[span, 1] == pytest.approx(0.02)
    assert highest[span, 1] == pytest.approx(0.002 * 10.099)
    assert np.isnan(lowest[-1, 1])
    assert np.isnan(highest[-1, 1])
    assert np.isfinite(lowest[449, 1])  # 44.9 .. 45.0 s: still there
    short = np.arange(100.0)
    kept = envelope(short, short, bins=600)
    assert all(part is short or np.array_equal(part, short) for part in kept)


def test_window_speeds_are_distance_over_time_per_span() -> None:
    t = np.linspace(0.0, 10.0, 10_001)
    track = np.stack([0.005 * t, np.where(t < 5.0, 0.01 * t, np.nan)], axis=1)
    edges, speeds = window_speeds(t, track, windows=10)
    np.testing.assert_allclose(edges, np.arange(11.0))
    np.testing.assert_allclose(speeds[:, 0], 0.005)
    np.testing.assert_allclose(speeds[:4, 1], 0.01)
    assert np.all(np.isnan(speeds[5:, 1]))  # 5 s and on: gone (nan at the span's end)


def test_a_long_run_draws_the_parts_over_the_whole_run(tmp_path: Path) -> None:
    params = FeederParameters(damping_ns_per_m=200.0, drive_frequency_hz=22.0).with_changes(
        drive_amplitude_n=70.0, track_length_m=1.0
    )
    parts = tuple(PartSpec(0.02 * k) for k in range(12))
    result = simulate(params, 30.0, 1000.0, parts=parts)
    paths = plot_result(result, params, tmp_path)
    assert [p.name for p in paths][-1] == "parts_over_run.png"
    image = imread(paths[-1])
    assert image.shape[0] > 500
    assert image.shape[1] > 800
    assert float(np.std(image)) > 0.01
    # the parts move: the speed the figure draws is the run's (track position over time)
    track = result.part_x_m - result.carrier_x_m[:, None]
    _, speeds = window_speeds(result.t_s, track)
    whole = (track[-1] - track[0]) / (result.t_s[-1] - result.t_s[0])
    np.testing.assert_allclose(np.nanmean(speeds[50:], axis=0), whole, rtol=0.1)
    assert np.all(whole > 0.005)
