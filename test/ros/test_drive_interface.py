"""The drive interface as a real process over DDS: lifecycle, services and their refusals, ramps on
the wire, heartbeat watchdog, e-stop latching, target-speed mode against the platform simulator,
and the Modbus TCP backend against an emulated feeder controller on loopback (the probe playing
the cell controller: ``ros_drive_cell``).

(Ten end-to-end scenarios over the same processes and probe helpers.)"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import pytest
import yaml
from diagnostic_msgs.msg import DiagnosticStatus
from lifecycle_msgs.msg import Transition
from rcl_interfaces.msg import Log, ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters
from ros_drive_cell import NODE, RELIABLE, SIMULATOR, drive_node, small_speed_table, stamp_s
from ros_test_tools import call, running, wait_until
from std_srvs.srv import Trigger

from feeder_ros.drive.limits import DriveLimits
from feeder_ros.drive.modbus import COMMAND_ENABLE, RegisterMap
from feeder_ros.drive.modbus_emulator import ControllerEmulator, free_port
from feeder_ros.identification.rational_fit import RationalModel
from feeder_ros.identification.speed_model_file import (
    ModelEntry,
    SpeedModelFile,
    identified_speed_table,
    save_speed_model,
)
from feeder_ros.msg import CarrierState, DriveCommand, DriveState
from feeder_ros.srv import SetDrive, SetTargetSpeed


def double(value: float) -> ParameterValue:
    return ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)


def text(value: str) -> ParameterValue:
    return ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=value)


def _amplitudes(commands: Sequence[DriveCommand]) -> list[float]:
    return [c.amplitude_percent if c.enabled else 0.0 for c in commands]


def _max_rate(commands: Sequence[DriveCommand], field: str) -> float:
    """Largest |change| per second between consecutive commands on the wire (by their stamps)."""
    rates = []
    for a, b in itertools.pairwise(commands):
        dt = stamp_s(b.header) - stamp_s(a.header)
        assert dt > 0.0, "drive commands must carry fresh, increasing stamps"
        va = getattr(a, field) if a.enabled else 0.0
        vb = getattr(b, field) if b.enabled else 0.0
        rates.append(abs(vb - va) / dt)
    return max(rates)


# the probe stands in for the simulator and publishes no parts/state: its liveness check is off
FAST = (
    "speed_model_enabled:=false",
    "max_amplitude_rate_percent_per_s:=20.0",
    "sim_feedback_timeout_s:=0.0",
)
CONFIG = Path(__file__).resolve().parents[2] / "config" / "drive_interface.yaml"


def _flatten(tree: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            flat.update(_flatten(value, f"{prefix}{key}."))
        else:
            flat[prefix + key] = value
    return flat


def test_config_file_lists_every_parameter_at_its_default() -> None:
    from feeder_ros.nodes.drive_interface import DEFAULTS, PARAMETERS

    tree = yaml.safe_load(CONFIG.read_text(encoding="utf-8"))
    values = _flatten(tree["/**/drive_interface"]["ros__parameters"])
    assert set(values) == set(PARAMETERS)
    for name, value in values.items():
        checked, default = PARAMETERS[name].check(value), DEFAULTS[name]
        nan = isinstance(default, float) and math.isnan(default)
        assert math.isnan(checked) if nan else checked == default, name


def test_config_file_is_applied_in_any_namespace(tmp_path: Path) -> None:
    text = CONFIG.read_text(encoding="utf-8")
    edited = tmp_path / "drive_interface.yaml"
    edited.write_text(
        text.replace("max_frequency_hz: 300.0", "max_frequency_hz: 250.0")
        .replace("port: 502", "port: 1502")
        .replace("speed_model_enabled: true", "speed_model_enabled: false"),
        encoding="utf-8",
    )
    ns = "/cell_b/feeder_2"
    with drive_node(ns, params_file=edited) as cell:
        request = GetParameters.Request(names=["max_frequency_hz", "modbus.port", "backend"])
        answer = call(cell.probe, GetParameters, f"{ns}/{NODE}/get_parameters", request)
        assert [answer.values[0].double_value, answer.values[1].integer_value] == [250.0, 1502]
        assert answer.values[2].string_value == "sim"
        cell.bring_up()
        clamped = cell.set_drive(280.0, 10.0, 0.0)
        assert clamped.result == SetDrive.Response.CLAMPED
        assert clamped.frequency_hz == 250.0
        # shutdown from active: output off, backend gone, the process still exits cleanly
        cell.start_heartbeat()
        assert cell.set_drive(30.0, 10.0, 0.0).result == SetDrive.Response.ACCEPTED
        assert cell.trigger("start").success
        assert wait_until(lambda: bool(cell.commands) and cell.commands[-1].enabled, 10.0)
        assert cell.transition(Transition.TRANSITION_ACTIVE_SHUTDOWN)
        assert cell.lifecycle_state() == "finalized"
        assert wait_until(lambda: not cell.commands[-1].enabled, 5.0)
        refused = cell.trigger("start")
        assert not refused.success
        assert "not configured" in refused.message


def test_unconfigured_node_refuses_and_parameters_are_validated() -> None:
    ns = "/drive_params"
    with drive_node(ns, *FAST) as cell:
        assert cell.lifecycle_state() == "unconfigured"
        assert wait_until(lambda: cell.last_diagnostic() is not None, 10.0)
        status = cell.last_diagnostic()
        assert status.level == DiagnosticStatus.WARN
        assert status.message == "unconfigured: output off"
        answer = cell.set_drive(30.0, 40.0, 0.0)
        assert answer.result == SetDrive.Response.REFUSED
        assert "not configured" in answer.reason
        assert not cell.trigger("start").success
        assert cell.set_speed(0.01).result == SetTargetSpeed.Response.REFUSED

        refused = cell.set_parameter("min_frequency_hz", double(400.0)).results[0]
        assert not refused.successful
        assert "must be below max_frequency_hz=300" in refused.reason
        bands = ParameterValue(type=ParameterType.PARAMETER_STRING, string_value="40, 50, 60")
        refused = cell.set_parameter("forbidden_bands_hz", bands).results[0]
        assert not refused.successful
        assert "pairs" in refused.reason
        assert cell.set_parameter("max_frequency_hz", double(200.0)).results[0].successful


def test_impossible_set_points_are_refused_and_change_nothing() -> None:
    """A frequency <= 0 Hz or NaN, a negative amplitude: no drive can do that, so set_drive
    refuses it naming the value (not CLAMPED onto the lowest frequency and driven): the running
    drive keeps its set point and output."""
    ns = "/drive_impossible"
    with drive_node(ns, *FAST) as cell:
        cell.bring_up()
        cell.start_heartbeat()
        assert cell.set_drive(30.0, 10.0, 0.0).result == SetDrive.Response.ACCEPTED
        started = cell.trigger("start")
        assert started.success, started.message
        cell.wait_state(DriveState.STATE_RUNNING)
        t_before = cell.now_s()
        for frequency, amplitude, reason in (
            (-20.0, 10.0, "frequency_hz=-20 must be > 0 Hz (this drive: 5-300 Hz)"),
            (0.0, 10.0, "frequency_hz=0 must be > 0 Hz (this drive: 5-300 Hz)"),
            (math.nan, 10.0, "frequency_hz=nan is not finite"),
            (30.0, -10.0, "amplitude_percent=-10 must be >= 0 % (this drive: 0-100 %)"),
        ):
            answer = cell.set_drive(frequency, amplitude, 0.0)
            assert answer.result == SetDrive.Response.REFUSED, answer
            assert answer.reason == reason
        t_after = cell.now_s()
        assert wait_until(lambda: len(cell.states_since(t_after)) >= 3, 5.0)
        assert wait_until(lambda: len(cell.commands_since(t_after)) >= 3, 5.0)
        for state in cell.states_since(t_before):
            assert state.state == DriveState.STATE_RUNNING
            assert (state.target_frequency_hz, state.target_amplitude_percent) == (30.0, 10.0)
            assert (state.frequency_hz, state.amplitude_percent) == (30.0, 10.0)
        for command in cell.commands_since(t_before):
            assert command.enabled
            assert (command.frequency_hz, command.amplitude_percent) == (30.0, 10.0)


def test_ramps_stop_estop_and_deactivate_on_the_wire() -> None:
    ns = "/drive_sim"
    with drive_node(ns, *FAST) as cell:
        cell.bring_up()
        assert wait_until(lambda: len(cell.commands) > 10, 10.0)
        assert not any(c.enabled for c in cell.commands)  # configured, not started: off
        assert cell.last_state().state == DriveState.STATE_IDLE

        refused = cell.trigger("start")
        assert not refused.success
        assert "no heartbeat received" in refused.message
        cell.start_heartbeat()
        # refused for the next reason once a beat has reached the node (the beats' delivery is
        # not awaited by start_heartbeat)
        refusals: list[Trigger.Response] = []

        def refused_for_want_of_a_set_point() -> bool:
            refusals.append(cell.trigger("start"))
            return "call set_drive" in refusals[-1].message

        assert wait_until(refused_for_want_of_a_set_point, 5.0), refusals[-1].message
        assert not any(r.success for r in refusals)
        bad = cell.set_drive(math.nan, 40.0, 0.0)
        assert bad.result == SetDrive.Response.REFUSED
        assert "frequency_hz=nan is not finite" in bad.reason
        clamped = cell.set_drive(450.0, 60.0, 0.0)
        assert clamped.result == SetDrive.Response.CLAMPED
        assert clamped.frequency_hz == 300.0
        assert "clamped to 300 Hz" in clamped.reason
        stored = cell.set_drive(30.0, 60.0, 0.0)
        assert stored.result == SetDrive.Response.ACCEPTED
        assert (stored.frequency_hz, stored.amplitude_percent) == (30.0, 60.0)
        assert abs(stored.ramp_time_s - 3.0) < 1e-9  # 60 % at 20 %/s
        assert "start to drive" in stored.reason

        # soft start: 0 -> 60 % at 20 %/s, seen as freshly stamped commands stepping up
        t_start = cell.now_s()
        started = cell.trigger("start")
        assert started.success, started.message
        assert "in 3.000 s" in started.message
        cell.wait_state(DriveState.STATE_RUNNING)
        # the top of the ramp goes out on drive/command in the tick that reports RUNNING on
        # drive/state: two writers, so it may arrive after the state
        assert wait_until(
            lambda: any(c.amplitude_percent == 60.0 for c in cell.commands_since(t_start)), 5.0
        )
        ramp = cell.commands_since(t_start)
        amplitudes = _amplitudes(ramp)
        assert max(amplitudes) == 60.0
        rising = [a for a in amplitudes if 0.0 < a < 60.0]
        assert len(rising) >= 30, "the ramp must step through intermediate amplitudes"
        assert rising == sorted(rising)
        assert _max_rate(ramp, "amplitude_percent") <= 20.0 * 1.05
        first_on = next(c for c in ramp if c.enabled)
        at_top = next(c for c in ramp if c.enabled and c.amplitude_percent == 60.0)
        assert stamp_s(at_top.header) - stamp_s(first_on.header) > 2.8
        assert all(c.frequency_hz == 30.0 for c in ramp if c.enabled)
        assert all(abs(c.amplitude_n - c.amplitude_percent) < 1e-9 for c in ramp)  # 100 N FS
        state = cell.last_state()
        assert (state.frequency_hz, state.amplitude_percent) == (30.0, 60.0)
        assert state.backend == "sim"

        # stop: ramps down (not a step), then enabled=false
        t_stop = cell.now_s()
        stopped = cell.trigger("stop")
        assert stopped.success
        assert "ramping to zero in 3.000 s" in stopped.message
        cell.wait_state(DriveState.STATE_IDLE)
        down = cell.commands_since(t_stop)
        falling = [a for a in _amplitudes(down) if 0.0 < a < 60.0]
        assert len(falling) >= 30
        assert falling == sorted(falling, reverse=True)
        assert _max_rate(down, "amplitude_percent") <= 20.0 * 1.05
        assert wait_until(lambda: not cell.commands[-1].enabled, 5.0)

        # e-stop: immediate zero, latched until reset
        assert cell.trigger("start").success
        cell.wait_state(DriveState.STATE_RUNNING)
        t_estop = cell.now_s()
        answer = cell.trigger("emergency_stop")
        t_answered = cell.now_s()
        assert answer.success
        estop = cell.wait_state(DriveState.STATE_ESTOP)
        assert estop.fault_reason == "emergency stop requested"
        assert estop.amplitude_percent == 0.0
        assert wait_until(lambda: len(cell.commands_since(t_estop)) > 20, 5.0)
        # the zero command is sent before the service answers; from it on, nothing is enabled
        # (not from t_estop: that is taken before the client's discovery of the service, while
        # the running output still went out)
        off = min(
            (c for c in cell.commands_since(t_estop) if not c.enabled),
            key=lambda c: stamp_s(c.header),
        )
        assert stamp_s(off.header) <= t_answered
        assert not any(c.enabled for c in cell.commands_since(stamp_s(off.header)))
        refused = cell.trigger("start")
        assert not refused.success
        assert "emergency stop latched" in refused.message
        assert cell.set_drive(30.0, 10.0, 0.0).result == SetDrive.Response.REFUSED
        time.sleep(0.5)
        assert cell.last_state().state == DriveState.STATE_ESTOP  # still latched
        reset = cell.trigger("reset_fault")
        assert reset.success
        assert "emergency stop requested" in reset.message
        cell.wait_state(DriveState.STATE_IDLE)

        # deactivate: ramps to zero, then off; commands refused while inactive
        assert cell.trigger("start").success
        cell.wait_state(DriveState.STATE_RUNNING)
        t_deactivate = cell.now_s()
        assert cell.transition(Transition.TRANSITION_DEACTIVATE)
        assert cell.lifecycle_state() == "inactive"
        cell.wait_state(DriveState.STATE_IDLE)
        assert wait_until(lambda: not cell.commands[-1].enabled, 5.0)  # (two writers, as above)
        down = cell.commands_since(t_deactivate)
        assert len([a for a in _amplitudes(down) if 0.0 < a < 60.0]) >= 30
        refused = cell.trigger("start")
        assert not refused.success
        assert "not active" in refused.message
        # what is read at configure stays as configured until cleanup (the same value passes)
        answer = cell.set_parameter("backend", text("modbus_tcp")).results[0]
        assert not answer.successful
        assert "backend is read at configure: deactivate and clean up" in answer.reason
        assert cell.set_parameter("backend", text("sim")).results[0].successful
        assert not cell.set_parameter("publish_rate_hz", double(20.0)).results[0].successful
        assert cell.set_parameter("max_amplitude_percent", double(90.0)).results[0].successful

        # cleanup: the backend is gone; drive/command and drive/state fall silent
        assert cell.transition(Transition.TRANSITION_CLEANUP)
        assert cell.lifecycle_state() == "unconfigured"
        assert cell.set_parameter("publish_rate_hz", double(20.0)).results[0].successful
        time.sleep(0.5)
        count = len(cell.commands)
        time.sleep(1.0)
        assert len(cell.commands) == count
        assert cell.set_drive(30.0, 10.0, 0.0).result == SetDrive.Response.REFUSED


def test_sim_backend_warns_while_no_simulator_listens() -> None:
    ns = "/drive_alone"
    with drive_node(ns, *FAST, "diagnostics_period_s:=0.2", listen=False) as cell:
        cell.bring_up()
        cell.start_heartbeat()

        def values() -> dict[str, str]:
            status = cell.last_diagnostic()
            return {} if status is None else {kv.key: kv.value for kv in status.values}

        expected = (
            "idle; backend: no subscriber on drive/command: is the platform simulator running?"
        )

        def active_and_warning() -> bool:  # (arrays from before the activation say "inactive")
            status = cell.last_diagnostic()
            return status is not None and status.message == expected

        assert wait_until(active_and_warning, 10.0), cell.last_diagnostic()
        status = cell.last_diagnostic()
        assert status.level == DiagnosticStatus.WARN
        assert values().get("drive/command subscribers") == "0"
        assert values()["backend connected"] == "True"
        assert cell.set_drive(30.0, 10.0, 0.0).result == SetDrive.Response.ACCEPTED
        started = cell.trigger("start")  # allowed: a simulator that joins follows the stream
        assert started.success, started.message
        assert started.message.endswith(
            "(backend: no subscriber on drive/command: is the platform simulator running?)"
        )
        cell.wait_state(DriveState.STATE_RUNNING)

        # a simulator (here the probe) subscribes: the warning clears, the commands arrive
        cell.listen_to_commands()
        assert wait_until(
            lambda: (
                values().get("drive/command subscribers") == "1"
                and cell.last_diagnostic().level == DiagnosticStatus.OK
            ),
            10.0,
        )
        assert cell.last_diagnostic().message == "running"
        assert values()["backend warning"] == ""
        assert wait_until(lambda: bool(cell.commands) and cell.commands[-1].enabled, 10.0)
        assert cell.commands[-1].amplitude_percent == 10.0


def test_watchdog_trips_within_its_timeout_and_ramps_to_zero() -> None:
    ns = "/drive_watchdog"
    with drive_node(ns, *FAST, "heartbeat_timeout_s:=1.5") as cell:
        logs: list[Log] = []
        cell.probe.create_subscription(Log, "/rosout", logs.append, RELIABLE)
        cell.bring_up()
        cell.start_heartbeat()
        assert wait_until(lambda: not math.isnan(cell.last_beat_s), 5.0)
        assert cell.set_drive(40.0, 50.0, 0.0).result == SetDrive.Response.ACCEPTED
        assert cell.trigger("start").success
        cell.wait_state(DriveState.STATE_RUNNING)
        assert wait_until(lambda: cell.last_diagnostic() is not None, 5.0)
        cell.beating = False
        time.sleep(0.2)
        last_beat = cell.last_beat_s
        fault = cell.wait_state(DriveState.STATE_FAULT, timeout_s=10.0)
        assert "heartbeat lost" in fault.fault_reason
        assert "timeout 1.5 s" in fault.fault_reason

        def logged() -> list[Log]:  # the trip is logged once, as an error, by the node
            return [
                entry
                for entry in list(logs)
                if entry.name == f"{ns[1:]}.drive_interface"
                and "fault latched: heartbeat lost" in entry.msg
            ]

        assert wait_until(lambda: bool(logged()), 5.0), [e.msg for e in logs]
        time.sleep(0.5)
        assert [entry.level for entry in logged()] == [Log.ERROR]
        first_fault = next(
            s for s in cell.states_since(last_beat) if s.state == DriveState.STATE_FAULT
        )
        tripped_after = stamp_s(first_fault.header) - last_beat
        assert 1.5 <= tripped_after <= 1.5 + 1.0, tripped_after  # generous: 2-core CI
        # ramped to zero at the rate limit (50 % at 20 %/s), then off; still FAULT (latched)
        assert wait_until(lambda: not cell.commands[-1].enabled, 10.0)
        down = cell.commands_since(stamp_s(first_fault.header))
        assert len([a for a in _amplitudes(down) if 0.0 < a < 50.0]) >= 20
        assert _max_rate(down, "amplitude_percent") <= 20.0 * 1.05
        assert cell.last_state().state == DriveState.STATE_FAULT

        def diagnostic_error() -> bool:
            status = cell.last_diagnostic()
            return status is not None and status.level == DiagnosticStatus.ERROR

        assert wait_until(diagnostic_error, 5.0)
        status = cell.last_diagnostic()
        assert status is not None
        assert "heartbeat lost" in status.message
        values = {kv.key: kv.value for kv in status.values}
        assert values["state"] == "fault"
        assert values["heartbeat timeout s"] == "1.5"
        refused = cell.trigger("start")
        assert not refused.success
        assert "fault latched" in refused.message
        cell.start_heartbeat()
        assert cell.trigger("reset_fault").success
        assert cell.trigger("start").success
        cell.wait_state(DriveState.STATE_RUNNING)


def test_target_speed_mode_drives_the_platform_simulator(tmp_path: Path) -> None:
    ns = "/drive_speed"
    params = (
        *small_speed_table(tmp_path),
        "min_frequency_hz:=10.0",
        "max_frequency_hz:=60.0",
        "max_amplitude_rate_percent_per_s:=100.0",
        "max_frequency_rate_hz_per_s:=100.0",
    )
    with (
        drive_node(ns, *params) as cell,
        running(
            [
                SIMULATOR,
                "--ros-args",
                "-r",
                f"__ns:={ns}",
                "-p",
                "imu_rate_hz:=100.0",
                "-p",
                "state_rate_hz:=100.0",
            ]
        ),
    ):
        carrier: list[CarrierState] = []
        cell.probe.create_subscription(
            CarrierState, f"{ns}/carrier/state", carrier.append, RELIABLE
        )
        cell.bring_up()
        assert list(tmp_path.glob("speed_table_*.npz")), "configure caches the speed table"
        cell.start_heartbeat()
        unreachable = cell.set_speed(5.0)
        assert unreachable.result == SetTargetSpeed.Response.REFUSED
        assert "speed 5 m/s unreachable within the limits; reachable" in unreachable.reason
        high = float(unreachable.reason.rsplit("..", 1)[1].split()[0])
        target = 0.5 * high
        answer = cell.set_speed(target)
        assert answer.result == SetTargetSpeed.Response.ACCEPTED, answer.reason
        assert abs(answer.predicted_speed_mps - target) < 1e-9
        assert 10.0 <= answer.frequency_hz <= 60.0
        assert 0.0 < answer.amplitude_percent <= 100.0
        assert cell.trigger("start").success
        state = cell.wait_state(DriveState.STATE_RUNNING)
        assert state.speed_mode
        assert abs(state.target_speed_mps - target) < 1e-12

        def simulator_driven() -> bool:
            if not carrier:
                return False
            last = carrier[-1]
            return (
                abs(last.drive_frequency_hz - answer.frequency_hz) < 1e-6
                and abs(last.drive_amplitude_n - answer.amplitude_percent) < 1e-6  # 100 N FS
            )

        assert wait_until(simulator_driven, 20.0), carrier[-1] if carrier else "no carrier state"
        assert cell.trigger("stop").success

        def simulator_stopped() -> bool:
            return bool(carrier) and carrier[-1].drive_amplitude_n == 0.0

        assert wait_until(simulator_stopped, 20.0)


def test_identified_speed_model_file_replaces_the_simulated_table(tmp_path: Path) -> None:
    """`feeder identify --model-out` -> drive interface: the requested speed is set where the
    identified G(s) predicts it; a broken model file fails the configure with the reason."""
    resonance = complex(-40.0, 2.0 * math.pi * 20.0)
    entries = tuple(
        ModelEntry(
            amplitude_percent=percent,
            amplitude_n=percent,  # full scale 100 N
            part_mass_kg=0.05,
            frequency_range_hz=(15.0, 30.0),
            fit_percent=90.0,
            model=RationalModel(
                gain=0.05 * percent, zeros=(), poles=(resonance, resonance.conjugate())
            ),
        )
        for percent in (30.0, 40.0, 50.0)
    )
    model_file = SpeedModelFile(full_scale_force_n=100.0, entries=entries, source="test")
    path = tmp_path / "speed_model.yaml"
    save_speed_model(path, model_file)
    limits = DriveLimits(
        min_frequency_hz=10.0, max_frequency_hz=60.0, max_amplitude_percent=100.0,
        full_scale_force_n=100.0,
    )  # fmt: skip
    expected_model = identified_speed_table(
        model_file, limits, part_mass_kg=0.05, frequency_steps=30
    )  # the node's default speed_model_frequency_steps
    low, high = expected_model.reachable_range()
    target = 0.5 * (low + high)
    expected = expected_model.choose(target)
    assert expected is not None
    params = (f"speed_model_file:={path}", "min_frequency_hz:=10.0", "max_frequency_hz:=60.0")
    with drive_node("/drive_identified", *params) as cell:
        cell.bring_up()
        answer = cell.set_speed(target)
        assert answer.result == SetTargetSpeed.Response.ACCEPTED, answer.reason
        assert answer.frequency_hz == pytest.approx(expected.frequency_hz, abs=1e-9)
        assert answer.amplitude_percent == pytest.approx(expected.amplitude_percent, abs=1e-9)
        assert 15.0 <= answer.frequency_hz <= 30.0  # inside the identified band
        assert answer.predicted_speed_mps == pytest.approx(target, rel=1e-9)
        refused = cell.set_speed(2.0 * high)
        assert refused.result == SetTargetSpeed.Response.REFUSED
        assert f"{high:.4g}" in refused.reason

    broken = tmp_path / "broken.yaml"
    broken.write_text(path.read_text().replace("full_scale_force_n", "full_scale"))
    with drive_node("/drive_identified_bad", f"speed_model_file:={broken}") as cell:
        assert not cell.transition(Transition.TRANSITION_CONFIGURE)
        assert cell.lifecycle_state() == "unconfigured"


def _registers(emulator: ControllerEmulator, names: Sequence[str]) -> list[int]:
    m = RegisterMap()
    return [emulator.register(getattr(m, name)) for name in names]


def test_modbus_backend_alarm_link_loss_and_reconnect() -> None:
    ns = "/drive_modbus"
    port = free_port()
    emulator = ControllerEmulator(port)
    emulator.start()
    params = (
        *FAST,
        "backend:=modbus_tcp",
        f"modbus.port:={port}",
        "modbus.poll_period_s:=0.02",
        "modbus.timeout_s:=2.0",  # the emulator shares a busy test process: no false link loss
        "modbus.reconnect_min_s:=0.1",
        "modbus.reconnect_max_s:=0.5",
        "diagnostics_period_s:=0.2",
    )
    try:
        with drive_node(ns, *params) as cell:
            cell.bring_up()
            cell.start_heartbeat()

            def diagnostic(predicate: Callable[[DiagnosticStatus, dict[str, str]], bool]) -> bool:
                status = cell.last_diagnostic()
                return status is not None and predicate(
                    status, {kv.key: kv.value for kv in status.values}
                )

            assert wait_until(
                lambda: diagnostic(lambda s, v: v.get("backend connected") == "True"), 15.0
            )
            assert cell.set_drive(31.5, 40.0, 0.0).result == SetDrive.Response.ACCEPTED
            assert cell.trigger("start").success
            cell.wait_state(DriveState.STATE_RUNNING)
            assert wait_until(
                lambda: (
                    _registers(emulator, ["command", "frequency", "amplitude"])
                    == [COMMAND_ENABLE, 315, 4000]
                ),
                10.0,
            )
            amplitudes = [w.get(RegisterMap().amplitude) for w in emulator.commands()]
            ramp = [a for a in amplitudes if a is not None and 0 < a < 4000]
            assert len(ramp) >= 20, "the soft start reaches the controller as a ramp"
            assert wait_until(
                lambda: diagnostic(
                    lambda s, v: (
                        s.level == DiagnosticStatus.OK
                        and v.get("controller actual_amplitude_percent") == "40.000"
                    )
                ),
                10.0,
            )
            state = cell.last_state()
            assert state.backend == "modbus_tcp"

            # controller-side alarm: fault, zero, reset needs the alarm acknowledged
            emulator.raise_alarm(17)
            fault = cell.wait_state(DriveState.STATE_FAULT)
            assert fault.fault_reason == "backend: controller alarm (code 17)"
            assert wait_until(lambda: emulator.register(RegisterMap().amplitude) == 0, 10.0)
            assert wait_until(
                lambda: diagnostic(
                    lambda s, v: s.level == DiagnosticStatus.ERROR and "code 17" in s.message
                ),
                10.0,
            )
            first = cell.trigger("reset_fault")
            assert not first.success
            assert "alarm reset sent to the controller" in first.message
            assert wait_until(lambda: cell.trigger("reset_fault").success, 10.0)
            cell.wait_state(DriveState.STATE_IDLE)
            assert emulator.register(RegisterMap().alarm_code) == 0

            # link loss: fault with the reason, reconnect with back-off when the controller returns
            assert cell.trigger("start").success
            cell.wait_state(DriveState.STATE_RUNNING)
            emulator.stop()
            lost = cell.wait_state(DriveState.STATE_FAULT)
            assert "backend: link to 127.0.0.1" in lost.fault_reason or (
                "backend: cannot connect" in lost.fault_reason
            )
            assert lost.amplitude_percent == 0.0
            assert wait_until(
                lambda: diagnostic(
                    lambda s, v: (
                        s.level == DiagnosticStatus.ERROR
                        and v.get("backend connected") == "False"
                        and "retry in 0.50 s" in v.get("backend fault", "")
                    )
                ),
                15.0,
            )
            refused = cell.trigger("reset_fault")
            assert not refused.success
            assert "backend still faulted" in refused.message
            emulator.start()
            assert wait_until(
                lambda: diagnostic(lambda s, v: v.get("backend connected") == "True"), 15.0
            )
            assert wait_until(lambda: cell.trigger("reset_fault").success, 10.0)
            status = cell.last_diagnostic()
            assert status is not None
            values = {kv.key: kv.value for kv in status.values}
            assert int(values["reconnects"]) >= 2
            assert cell.trigger("start").success
            cell.wait_state(DriveState.STATE_RUNNING)
            assert wait_until(lambda: emulator.register(RegisterMap().amplitude) == 4000, 10.0)
            # deactivate ramps the controller's set point to zero and switches it off
            assert cell.transition(Transition.TRANSITION_DEACTIVATE)
            assert wait_until(
                lambda: _registers(emulator, ["command", "amplitude"]) == [0, 0], 10.0
            )
    finally:
        emulator.stop()
