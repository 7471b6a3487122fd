"""Sweep plans (parsing, refusals naming the value), the offline source against direct
``simulate_many`` calls, CSV round trips and refusals, and grouping for the fit."""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import pytest

from feeder_ros.cli.sim import default_config_path, load_parameters
from feeder_ros.identification.offline_sweep import (
    ENDLESS_TRACK_M,
    offline_points,
    offline_sweep,
    travel_time,
)
from feeder_ros.identification.sweep import (
    CSV_COLUMNS,
    SweepDataError,
    SweepPlan,
    SweepPlanError,
    SweepPoint,
    SweepResult,
    check_fit_data,
    parse_orders,
    parse_values,
)
from feeder_ros.physics.simulation import FeederSimulator, PartSpec, simulate_many

REALISTIC = load_parameters(default_config_path(), preset="realistic")


def plan(**changes: object) -> SweepPlan:
    values: dict[str, object] = {
        "frequencies_hz": "20:21:0.5",
        "amplitudes_percent": [40],
        "part_masses_kg": [0.05],
        "settle_s": 0.5,
        "window_s": 1.0,
    }
    values.update(changes)
    return SweepPlan.from_mapping(values)


# ------------------------------------------------------------------------------------ parsing


def test_ranges_include_stop_and_land_on_the_grid() -> None:
    values = parse_values("frequencies_hz", "38:58:0.5")
    assert len(values) == 41
    assert values[0] == 38.0
    assert values[-1] == 58.0
    assert values[7] == 41.5  # exactly, no 41.500000000001
    assert parse_values("f", "38:38.35:0.1") == (38.0, 38.1, 38.2, 38.3)  # stop off the grid
    assert parse_values("f", "20, 21:23:1, 30") == (20.0, 21.0, 22.0, 23.0, 30.0)
    assert parse_values("f", [35, "37", 39.5]) == (35.0, 37.0, 39.5)
    assert parse_values("f", 41) == (41.0,)


@pytest.mark.parametrize(
    ("spec", "needle"),
    [
        ("38:58:0", "frequencies_hz='38:58:0': the step must be > 0"),
        ("58:38:1", "frequencies_hz='58:38:1': stop is below start"),
        ("38:58", "frequencies_hz='38:58': a range is start:stop:step"),
        ("38, fast", "frequencies_hz='fast': not a number"),
        ("nan", "frequencies_hz='nan': not finite"),
        ("1:100000:0.001", "at most 10000"),
        ("", "no values"),
        (True, "frequencies_hz=True: not a number"),
        ({"a": 1}, "expected a number, a list or a range"),
    ],
)
def test_bad_values_are_refused_naming_them(spec: object, needle: str) -> None:
    with pytest.raises(SweepPlanError) as error:
        parse_values("frequencies_hz", spec)
    assert needle in str(error.value)


def test_orders_parse_and_refuse() -> None:
    assert parse_orders("1/2, 1/3,2/4") == ((1, 2), (1, 3), (2, 4))
    assert parse_orders([[0, 2], "1/2", "1/2"]) == ((0, 2), (1, 2))  # duplicates dropped
    for spec, needle in [
        ("3/2", "'3/2': more zeros than poles"),
        ("1/0", "'1/0': needs >= 1 pole"),
        ("one/two", "'one/two': expected zeros/poles"),
        ("", "no orders"),
        ("1/9", "more than 8 poles"),
    ]:
        with pytest.raises(SweepPlanError, match="orders") as error:
            parse_orders(spec)
        assert needle in str(error.value)


# --------------------------------------------------------------------------------------- plan


def test_plan_from_mapping_sorts_and_maps_amplitude_to_force() -> None:
    p = plan(amplitudes_percent="50, 30", full_scale_force_n=80.0)
    assert p.frequencies_hz == (20.0, 20.5, 21.0)
    assert p.amplitudes_percent == (30.0, 50.0)
    assert p.amplitude_n(50.0) == 40.0
    assert p.point_count == 6
    assert list(p.settings())[:4] == [
        (0.05, 30.0, 20.0),
        (0.05, 30.0, 20.5),
        (0.05, 30.0, 21.0),
        (0.05, 50.0, 20.0),
    ]
    assert "20-21 Hz (3 frequencies)" in p.describe()
    # a distance replaces the base's window, and back
    d = SweepPlan.from_mapping({"distance_m": 0.085}, base=p)
    assert d.window_s is None
    assert d.distance_m == 0.085
    w = SweepPlan.from_mapping({"window_s": 2.0}, base=d)
    assert w.window_s == 2.0
    assert w.distance_m is None


@pytest.mark.parametrize(
    ("changes", "needle"),
    [
        ({"amplitudes_percent": [40, 150]}, "amplitudes_percent=150.0: must lie in (0, 100]"),
        ({"part_masses_kg": "-0.01"}, "part_masses_kg=-0.01: must lie in (0, 1000]"),
        ({"frequencies_hz": "20, 20"}, "frequencies_hz=(20.0, 20.0): a value appears twice"),
        (
            {"frequencies_hz": [21, 20, 20.000000001]},
            "frequencies_hz=(21.0, 20.0, 20.000000001): two frequencies within 1e-06 Hz are one",
        ),
        ({"settle_s": -1}, "settle_s=-1: >= 0 required"),
        ({"window_s": 0}, "window_s=0: > 0 required"),
        ({"window_s": 90}, "window_s=90: exceeds max_window_s"),
        ({"distance_m": 0.085}, "give exactly one"),
        ({"speed": 3}, "speed=3: unknown field"),
        ({"full_scale_force_n": "big"}, "full_scale_force_n='big': not a number"),
    ],
)
def test_bad_plans_are_refused_naming_the_value(changes: dict[str, object], needle: str) -> None:
    with pytest.raises(SweepPlanError) as error:
        plan(**changes)
    assert needle in str(error.value)


def test_frequencies_just_beyond_the_resolution_are_two() -> None:
    assert plan(frequencies_hz=[20.0, 20.00001]).frequencies_hz == (20.0, 20.00001)


def test_a_plan_needs_the_grid() -> None:
    with pytest.raises(SweepPlanError, match="part_masses_kg=None: required"):
        SweepPlan.from_mapping({"frequencies_hz": 20, "amplitudes_percent": 40})
    with pytest.raises(SweepPlanError, match="expected a mapping"):
        SweepPlan.from_mapping(["frequencies_hz"])  # type: ignore[arg-type]


def test_the_shipped_plan_is_valid() -> None:
    import yaml

    document = yaml.safe_load((default_config_path().parent / "identify.yaml").read_text())
    p = SweepPlan.from_mapping(document["sweep"])
    assert p.frequencies_hz[0] == 19.0
    assert p.frequencies_hz[-1] == 27.5
    assert len(p.frequencies_hz) == 18
    assert parse_orders(document["fit"]["orders"])


# ---------------------------------------------------------------------------- offline source


def test_offline_sweep_equals_direct_simulate_many() -> None:
    p = plan(amplitudes_percent=[30, 40], part_masses_kg=[0.031, 0.06])
    result = offline_sweep(REALISTIC, p)
    assert result.source == "sim"
    assert len(result) == 12
    assert result.ok_count == 12
    for mass in p.part_masses_kg:
        direct_points = [
            REALISTIC.with_changes(
                drive_frequency_hz=f,
                drive_amplitude_n=a / 100.0 * p.full_scale_force_n,
                part_mass_kg=mass,
                track_length_m=ENDLESS_TRACK_M,
            )
            for a in p.amplitudes_percent
            for f in p.frequencies_hz
        ]
        direct = simulate_many(direct_points, 1.0, part=PartSpec(), settle_s=0.5)
        mine = [q for q in result.points if q.part_mass_kg == mass]
        assert [(q.amplitude_percent, q.frequency_hz) for q in mine] == [
            (a, f) for a in p.amplitudes_percent for f in p.frequencies_hz
        ]
        np.testing.assert_array_equal([q.speed_mps for q in mine], direct.mean_part_speed_mps)
        np.testing.assert_array_equal([q.slip_fraction for q in mine], direct.slip_fraction)
        assert all(q.duration_s == 1.0 for q in mine)
        assert [q.amplitude_n for q in mine] == [30.0] * 3 + [40.0] * 3
    # the mass is the point's: M_eq differs, so do the speeds (slightly)
    light = [q.speed_mps for q in result.points if q.part_mass_kg == 0.031]
    heavy = [q.speed_mps for q in result.points if q.part_mass_kg == 0.06]
    assert light != heavy
    assert all(q.speed_mps > 0.01 for q in result.points)  # the resonance near 20.5 Hz


def test_offline_distance_mode_times_the_first_arrival_along_the_track() -> None:
    p = plan(frequencies_hz="20:22:1", amplitudes_percent=[1, 40], distance_m=0.01, window_s=None)
    result = offline_sweep(REALISTIC, p)
    moving = [q for q in result.points if q.amplitude_percent == 40.0]
    assert all(q.ok for q in moving)
    for q in moving:
        assert q.speed_mps == 0.01 / q.duration_s
        # an independent run on the endless track, sampled densely: the part's track position
        # (lab - carrier) is 1 cm ahead of where it was at settle_s exactly at the reported end
        # of the window, and not before
        point = REALISTIC.with_changes(
            drive_frequency_hz=q.frequency_hz,
            drive_amplitude_n=q.amplitude_n,
            part_mass_kg=q.part_mass_kg,
            track_length_m=ENDLESS_TRACK_M,
        )
        end = p.settle_s + q.duration_s
        t = np.concatenate([np.linspace(p.settle_s, end, 20001), [end + 0.01]])
        run = FeederSimulator(point, (PartSpec(),))
        run.advance(p.settle_s)
        samples = run.advance(end + 0.01, t)
        travel = samples.part_x_m[:, 0] - samples.carrier_x_m
        travel -= travel[0]
        assert travel[-2] == pytest.approx(0.01, abs=1e-12)
        assert np.all(travel[:-2] < 0.01)
    # at 1 N the carrier never reaches the slip threshold: the part sticks and goes nowhere
    still = [q for q in result.points if q.amplitude_percent == 1.0]
    assert all(not q.ok for q in still)
    assert all(q.duration_s == p.max_window_s for q in still)
    assert all(abs(q.speed_mps) < 1e-12 and q.slip_fraction == 0.0 for q in still)
    assert "did not travel 0.01 m within max_window_s=60 s" in still[0].reason


@pytest.mark.parametrize("distance", [0.0, -0.01, math.nan, math.inf])
def test_travel_time_refuses_a_bad_distance(distance: float) -> None:
    point = offline_points(REALISTIC, plan())[0][3]
    with pytest.raises(ValueError, match=f"distance_m={distance!r} must be a positive number"):
        travel_time(point, distance, 0.5, 10.0)


def test_offline_sweep_refuses_the_smooth_model() -> None:
    with pytest.raises(ValueError, match="stiffness_model='logistic'"):
        offline_sweep(REALISTIC.with_changes(stiffness_model="logistic"), plan())


# ---------------------------------------------------------------------------- CSV and groups


def _result() -> SweepResult:
    points = [
        SweepPoint(20.0, 40.0, 40.0, 0.05, 0.016, 3.0, 0.4),
        SweepPoint(21.0, 40.0, 40.0, 0.05, 1 / 3, 3.0, 0.5),
        SweepPoint(21.0, 40.0, 40.0, 0.05, 0.5, 3.0),  # a repeat: averaged in the group
        SweepPoint(22.0, 40.0, 40.0, 0.05, -0.002, 3.0),  # backwards: left out of the fit
        SweepPoint(23.0, 40.0, 40.0, 0.05, math.nan, 0.0, ok=False, reason="refused, a, b"),
        SweepPoint(20.0, 30.0, 30.0, 0.05, 0.01, 3.0),
    ]
    return SweepResult(tuple(points), "test", 100.0)


def test_csv_round_trip_is_exact(tmp_path: Path) -> None:
    result = _result()
    path = tmp_path / "sweep.csv"
    with path.open("w", encoding="utf-8", newline="") as stream:
        result.write_csv(stream)
    assert path.read_text().splitlines()[0] == ",".join(CSV_COLUMNS)
    back = SweepResult.read_csv(path)
    assert back.full_scale_force_n == 100.0
    assert len(back) == len(result)
    for a, b in zip(back.points, result.points, strict=True):
        for name in CSV_COLUMNS:
            x, y = getattr(a, name), getattr(b, name)
            assert (x == y) or (isinstance(x, float) and math.isnan(x) and math.isnan(y)), name


def _csv(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "bad.csv"
    path.write_text(text, encoding="utf-8")
    return path


def test_bad_csv_is_refused_with_line_and_column(tmp_path: Path) -> None:
    buffer = io.StringIO()
    _result().write_csv(buffer)
    lines = buffer.getvalue().splitlines()
    bad_speed = lines[1].replace("0.016", "nan")
    with pytest.raises(SweepDataError, match=r"line 2: speed_mps=nan in a usable row \(ok=1\)"):
        SweepResult.read_csv(_csv(tmp_path, "\n".join([lines[0], bad_speed])))
    with pytest.raises(SweepDataError, match=r"line 2: frequency_hz='fast' is not a number"):
        SweepResult.read_csv(_csv(tmp_path, "\n".join([lines[0], "fast" + lines[1][4:]])))
    with pytest.raises(SweepDataError, match="missing column"):
        SweepResult.read_csv(_csv(tmp_path, "frequency_hz,speed_mps\n20,0.01\n"))
    with pytest.raises(SweepDataError, match="no points"):
        SweepResult.read_csv(_csv(tmp_path, lines[0] + "\n"))
    with pytest.raises(SweepDataError, match="cannot read"):
        SweepResult.read_csv(tmp_path / "missing.csv")
    mixed = lines[1].replace("40.0,40.0", "40.0,80.0")  # 200 N full scale against 100 N
    with pytest.raises(SweepDataError, match="full scales"):
        SweepResult.read_csv(_csv(tmp_path, "\n".join([lines[0], lines[1], lines[2], mixed])))


def test_groups_per_amplitude_and_mass() -> None:
    groups = _result().groups()
    assert [(g.amplitude_percent, g.part_mass_kg) for g in groups] == [(30.0, 0.05), (40.0, 0.05)]
    g = groups[1]
    np.testing.assert_array_equal(g.frequency_hz, [20.0, 21.0])
    np.testing.assert_allclose(g.speed_mps, [0.016, (1 / 3 + 0.5) / 2])
    assert g.amplitude_n == 40.0
    assert g.excluded == {
        "refused, a, b": 1,
        "speed not above 0 m/s (part not moving forward)": 1,
    }
    assert g.label == "40 % / 50 g"
    # a higher floor leaves the slow point out too
    assert groups[1].frequency_hz.size - _result().groups(0.02)[1].frequency_hz.size == 1


def test_fit_data_checks_give_the_reason() -> None:
    with pytest.raises(SweepDataError, match=r"a single frequency \(20 Hz, 3 point\(s\)\)"):
        check_fit_data([20.0, 20.0, 20.0], [0.01, 0.011, 0.012], 4)
    with pytest.raises(SweepDataError, match=r"only 3 usable point\(s\).*at least 6"):
        check_fit_data([20.0, 21.0, 22.0], [0.01, 0.02, 0.01], 6)
    with pytest.raises(SweepDataError, match=r"1 non-finite value.*21 Hz"):
        check_fit_data([20.0, 21.0, 22.0], [0.01, math.nan, 0.01], 2)
    with pytest.raises(SweepDataError, match="no usable points"):
        check_fit_data([], [], 2)
    check_fit_data([20.0, 21.0, 22.0], [0.01, 0.02, 0.01], 3)  # enough
