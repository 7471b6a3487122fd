"""The cell's view of a run in ``feeder analyze``: headline figures, target against actual, faults
and the diagnostics in clock time, from a bag whose every figure is known by hand (run_bag.py);
the terminal summary and the report say the same."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from bag.run_bag import EXPECTED, FAULT, T0, write_run_bag

from feeder_ros.bag.analysis import analyze_bag
from feeder_ros.bag.presentation import clock, duration, sections
from feeder_ros.bag.report import format_summary, write_outputs
from feeder_ros.bag.run_log import HOLD_LIMIT, Series


def test_headline_figures_are_the_runs(tmp_path: Path) -> None:
    write_run_bag(tmp_path / "bag")
    result = analyze_bag(tmp_path / "bag")
    figures = result.figures
    assert figures is not None
    assert figures.run_s == pytest.approx(EXPECTED["run_s"])
    assert figures.driving_s == pytest.approx(EXPECTED["driving_s"])
    assert figures.target_s == pytest.approx(EXPECTED["target_s"])
    assert figures.at_target_s == pytest.approx(EXPECTED["at_target_s"])
    assert figures.parts_fed == EXPECTED["parts"]
    assert figures.feed_rate_per_min == pytest.approx(EXPECTED["parts"] / 1.0)
    [fault] = figures.faults
    assert (fault.start_s, fault.end_s, fault.state, fault.reason) == pytest.approx(
        (FAULT[0], FAULT[1], "fault", FAULT[2])
    )
    # each segment's target is the one the monitor held during it
    pairs = [(s.frequency_hz, s.amplitude_n, s.target_speed_mps) for s in result.segments]
    assert [p[:2] for p in pairs] == [(30.0, 20.0), (40.0, 20.0), (0.0, 0.0), (40.0, 20.0),
                                      (0.0, 0.0)]  # fmt: skip
    assert [p[2] for p in pairs[:4]] == pytest.approx([0.010, 0.008, 0.008, 0.008])
    assert math.isnan(pairs[4][2])


def test_the_summary_and_the_report_show_the_same_rounded_figures(tmp_path: Path) -> None:
    write_run_bag(tmp_path / "bag")
    result = analyze_bag(tmp_path / "bag")
    [section] = sections([result])
    facts = {f.key: f.value for f in section.headline}
    assert facts == {
        "run_time": "1 min 00 s",
        "parts_fed": "19",
        "feed_rate": "19.0 /min",
        "driving_time": "37.0 s",
        "time_at_target": "68 % (25.0 s of 37.0 s)",
        "faults": "1 (3.0 s)",
    }
    fault_clock = clock(T0, FAULT[0])
    assert fault_clock == "15:07:10"  # T0 is 15:06:40 UTC
    [faults] = [t for t in section.tables if t.key == "faults"]
    assert faults.rows == [["15:07:10", "30.0", "3.0 s", "fault", FAULT[2]]]
    [segments] = [t for t in section.tables if t.key == "segments"]
    headers = [c.header for c in segments.columns]
    assert segments.rows[0][headers.index("target [mm/s]")] == "10.00"
    assert segments.rows[4][headers.index("target [mm/s]")] == "-"

    text = format_summary([result])
    for fact in section.headline:
        assert f"{fact.label}: " in text
        assert fact.value in text
    assert "15:07:10" in text
    write_outputs([result], tmp_path / "out")
    page = (tmp_path / "out" / "report.html").read_text()
    for fact in section.headline:
        assert f"<div data-key='{fact.key}'><dt>{fact.label}</dt><dd>{fact.value}</dd>" in page
    # speed and drive over time only: no segment has a speed (no estimate, truth or transits)
    assert page.count("data:image/png;base64,") == 1
    document = json.loads((tmp_path / "out" / "analysis.json").read_text())
    headline = document["bags"][0]["headline"]
    assert headline["parts_fed"] == EXPECTED["parts"]
    assert headline["at_target_share"] == pytest.approx(25.0 / 37.0)
    assert headline["faults"][0]["duration_s"] == pytest.approx(3.0)
    rows = (tmp_path / "out" / "bag_segments.csv").read_text().splitlines()
    assert "target_speed_mm_s" in rows[0].split(",")


def test_a_bag_without_the_cells_view_says_so() -> None:
    from feeder_ros.bag.presentation import headline
    from feeder_ros.bag.run_log import RunFigures

    figures = RunFigures(12.0, math.nan, math.nan, math.nan, 3, 15.0, ())
    facts = {f.key: f.value for f in headline(figures)}
    assert facts["time_at_target"] == "- (no speed/status recorded)"
    assert "driving_time" not in facts
    assert facts["faults"] == "0"


@pytest.mark.parametrize(
    ("seconds", "text"),
    [(0.04, "0.0 s"), (59.94, "59.9 s"), (59.96, "1 min 00 s"), (754.4, "12 min 34 s"),
     (3 * 3600 + 7 * 60 + 29, "3 h 07 min"), (math.nan, "-")],
)  # fmt: skip
def test_durations_read_as_long_as_they_need(seconds: float, text: str) -> None:
    assert duration(seconds) == text


def test_simulated_time_has_no_clock_time() -> None:
    assert clock(5_000_000_000, 1.0) == ""  # a simulation's /clock starts near zero
    assert clock(None, 1.0) == ""


def test_a_recording_gap_is_not_counted_as_time_held() -> None:
    import numpy as np

    t = np.array([0, 1, 2, 3, 100], dtype=np.int64) * 1_000_000_000
    held = Series(t, {}).held_s(end_ns=101 * 1_000_000_000)
    assert list(held) == [1.0, 1.0, 1.0, HOLD_LIMIT * 1.0, 1.0]
