"""Resonance tracking coordinated with the controller, and the drive's health, without ROS: the
real DriveController and ResonanceTracker over a synthetic resonance (the decisions the drive
interface's shell used to make itself)."""

from __future__ import annotations

import pytest

from feeder_ros.drive.backend import BackendStatus, DriveOutput
from feeder_ros.drive.controller import DriveController
from feeder_ros.drive.health import Level, drive_health, drive_values
from feeder_ros.drive.limits import DriveLimits
from feeder_ros.drive.resonance_tracker import TrackerSettings
from feeder_ros.drive.tracked_control import TrackedControl, apply_loop_point

LIMITS = DriveLimits(min_frequency_hz=10.0, max_frequency_hz=30.0, max_amplitude_percent=80.0)
SETTINGS = TrackerSettings(dither_period_s=3.0, settle_s=0.8, feedback_timeout_s=2.0)
CONNECTED = BackendStatus(connected=True)


def speed_at(f: float, a: float) -> float:
    """A resonance peak at 21 Hz, proportional to the amplitude."""
    x = (f - 21.0) / 2.0
    return 1e-4 * a / (1.0 + x * x)


class Cell:
    def __init__(self) -> None:
        self.log: list[tuple[str, str]] = []
        self.controller = DriveController(LIMITS, heartbeat_timeout_s=100.0)
        self.tracked = TrackedControl(SETTINGS, LIMITS, lambda s, t: self.log.append((s, t)))
        self.tracked.enabled = True
        self.t = 0.0
        self.controller.activate(0.0)
        self.controller.heartbeat(0.0)

    def speed_mode(self, f: float, a: float) -> None:
        """Target-speed mode at (f, a), as set_target_speed leaves it (no speed model needed)."""
        assert apply_loop_point(self.controller, self.t, f, a).outcome == 0
        self.controller.speed_mode, self.controller.target_speed_mps = True, speed_at(21.0, a)

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / 0.05)):
            self.t = round(self.t + 0.05, 9)
            out = self.controller.tick(self.t, 0.05)
            self.tracked.feedback(self.t, speed_at(out.frequency_hz, out.amplitude_percent))
            self.tracked.tick(self.controller, self.t)


def test_tracking_runs_only_in_target_speed_mode_and_holds_its_point_when_stopped() -> None:
    cell = Cell()
    cell.speed_mode(18.0, 40.0)
    cell.run(1.0)
    assert not cell.tracked.active
    assert cell.tracked.note == "not running (start)"
    assert cell.controller.start(cell.t).success
    cell.run(30.0)
    assert cell.tracked.active
    assert cell.controller.speed_mode  # the tracker's set points keep target-speed mode
    assert ("info", "resonance tracking started at 18.000 Hz, 40.00 % for 0.004 m/s") in cell.log
    status = cell.tracked.status(cell.t)
    assert status.centre_frequency_hz > 19.0  # moved toward the peak at 21 Hz
    values = cell.tracked.values(cell.t, "estimate (vehicle_estimate)")
    assert values["resonance tracking"] == "active"
    assert values["tracking feedback"] == "estimate (vehicle_estimate)"

    # stopped in target-speed mode: the tracked point becomes the stored set point
    centre = status.centre_frequency_hz
    cell.controller.stop(cell.t)
    cell.run(0.1)
    assert not cell.tracked.active
    assert cell.tracked.note == "not running (start)"
    assert cell.controller.set_point.frequency_hz == pytest.approx(centre)
    assert any(t.startswith("resonance tracking stopped (not running") for _, t in cell.log)

    # set_drive leaves target-speed mode: tracking does not start and holds nothing
    assert cell.controller.set_drive(cell.t, 15.0, 30.0, 0.0).outcome == 0
    assert cell.controller.start(cell.t).success
    cell.run(2.0)
    assert not cell.tracked.active
    assert cell.tracked.note == "not in target-speed mode (set_target_speed)"
    assert cell.controller.set_point.frequency_hz == 15.0


def test_a_refused_start_is_logged_once_and_retried_for_a_new_target() -> None:
    cell = Cell()
    cell.speed_mode(18.0, 40.0)
    cell.controller.target_speed_mps = 0.0  # no speed peak to track
    assert cell.controller.start(cell.t).success
    cell.run(3.0)
    warnings = [t for s, t in cell.log if s == "warning"]
    assert warnings == ["resonance tracking cannot start: target speed 0: no speed peak to track"]
    assert not cell.tracked.active
    assert cell.tracked.note == "target speed 0: no speed peak to track"
    cell.controller.target_speed_mps = 0.003
    cell.tracked.new_target()
    cell.run(0.5)
    assert cell.tracked.active


def test_health_ranks_the_most_serious_first_and_warns_only_an_ok_drive() -> None:
    c = DriveController(LIMITS, heartbeat_timeout_s=2.0)
    c.heartbeat(0.0)
    assert drive_health(c, CONNECTED, 0.0).level is Level.WARN
    assert drive_health(c, CONNECTED, 0.0).summary == "inactive: idle"
    c.activate(0.0)
    c.tick(0.0)
    assert drive_health(c, CONNECTED, 0.0) == drive_health(c, CONNECTED, 1.0)
    assert drive_health(c, CONNECTED, 1.0).level is Level.OK
    assert drive_health(c, CONNECTED, 5.0).summary == "idle; no heartbeat"
    backend = BackendStatus(connected=True, fault="link lost")
    assert drive_health(c, backend, 1.0).summary == "backend: link lost"
    assert drive_health(c, backend, 1.0).level is Level.ERROR
    assert drive_health(c, BackendStatus(connected=False), 1.0).summary == "backend not connected"
    ok = drive_health(c, CONNECTED, 1.0, amplitude_warning="at the drive's limit")
    assert (ok.level, ok.summary) == (
        Level.WARN,
        "idle; amplitude regulation: at the drive's limit",
    )
    c.emergency_stop(1.0, "button")
    c.tick(1.0)
    health = drive_health(c, CONNECTED, 1.0, amplitude_warning="at the drive's limit")
    assert (health.level, health.summary) == (Level.ERROR, "estop: button")
    assert [int(level) for level in Level] == [0, 1, 2]  # DiagnosticStatus's OK, WARN, ERROR


def test_drive_values_report_output_set_point_heartbeat_and_backend() -> None:
    c = DriveController(LIMITS, heartbeat_timeout_s=2.0)
    output = DriveOutput(True, 21.0, 40.0, 12.5)
    linked = BackendStatus(connected=True, warning="slow link", details={"port": "502"})
    values = drive_values(c, linked, output, 0.0)
    assert values["heartbeat age s"] == "never"
    assert (values["state"], values["active"], values["output enabled"]) == (
        "idle",
        "False",
        "True",
    )
    assert (values["frequency_hz"], values["amplitude_percent"], values["amplitude_n"]) == (
        "21.000",
        "40.000",
        "12.500",
    )
    assert (values["backend warning"], values["port"]) == ("slow link", "502")
    assert "controller actual_frequency_hz" not in values
    c.heartbeat(1.0)
    read_back = BackendStatus(
        connected=True, actual_frequency_hz=20.9, actual_amplitude_percent=39.5
    )
    values = drive_values(c, read_back, output, 1.5)
    assert (values["heartbeat age s"], values["heartbeat timeout s"]) == ("0.500", "2")
    assert values["controller actual_frequency_hz"] == "20.900"
    assert values["controller actual_amplitude_percent"] == "39.500"
