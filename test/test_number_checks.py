"""One rule for "a number" across the settings objects (``is_number``): NumPy scalars read from
arrays (np.int64, np.float32) are numbers like Python's, and booleans (Python's or NumPy's) are
refused by name, not taken as 0 or 1."""

from __future__ import annotations

import numpy as np
import pytest

from feeder_ros.design.space import DesignError, DesignVariable
from feeder_ros.drive.resonance_tracker import TrackerError, TrackerSettings
from feeder_ros.identification.sweep import SweepPlan, SweepPlanError, parse_values
from feeder_ros.monitoring.speed_monitor import MonitorConfig
from feeder_ros.physics.parameters import ParameterError

PLAN = {
    "frequencies_hz": "20:21:0.5",
    "amplitudes_percent": [40],
    "part_masses_kg": [0.05],
    "window_s": 1.0,
}


def test_numpy_scalars_are_numbers() -> None:
    assert TrackerSettings(dither_hz=np.float32(0.5)).dither_hz == 0.5
    assert TrackerSettings(max_step_hz=np.int64(2)).max_step_hz == 2.0
    assert MonitorConfig(stall_time_s=np.int64(4)).stall_time_s == 4
    assert MonitorConfig(clear_ratio=np.float32(0.5)).clear_ratio == 0.5
    variable = DesignVariable("plate_count", np.int64(1), np.int64(4))
    assert (variable.lower, variable.upper) == (1.0, 4.0)
    assert parse_values("frequencies_hz", np.int64(41)) == (41.0,)
    assert parse_values("frequencies_hz", [np.float32(20.5), np.int64(30)]) == (20.5, 30.0)
    plan = SweepPlan.from_mapping(
        {**PLAN, "amplitudes_percent": [np.int64(40)], "settle_s": np.int64(1)}
    )
    assert (plan.amplitudes_percent, plan.settle_s) == ((40.0,), 1.0)


@pytest.mark.parametrize("flag", [True, np.bool_(True)])
def test_booleans_are_refused_by_name(flag: object) -> None:
    with pytest.raises(TrackerError, match=rf"^dither_hz={flag!r} is not a number$"):
        TrackerSettings(dither_hz=flag)  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match=rf"^stall_time_s={flag!r} must be finite and > 0$"):
        MonitorConfig(stall_time_s=flag)  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match=rf"^clear_ratio={flag!r} must be in \[0, 1\]$"):
        MonitorConfig(clear_ratio=flag)  # type: ignore[arg-type]
    with pytest.raises(DesignError, match=rf"lower bound {flag!r} is not a number"):
        DesignVariable("plate_count", flag, 4)  # type: ignore[arg-type]
    with pytest.raises(SweepPlanError, match=rf"frequencies_hz={flag!r}: not a number"):
        parse_values("frequencies_hz", flag)
    with pytest.raises(SweepPlanError, match=rf"frequencies_hz={flag!r}: not a number"):
        parse_values("frequencies_hz", [20.0, flag])
    with pytest.raises(SweepPlanError, match=rf"settle_s={flag!r}: not a number"):
        SweepPlan.from_mapping({**PLAN, "settle_s": flag})
    with pytest.raises(SweepPlanError, match=rf"amplitudes_percent={flag!r}: not a number"):
        SweepPlan.from_mapping({**PLAN, "amplitudes_percent": [flag]})
