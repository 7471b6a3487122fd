"""A probe playing the cell controller of a drive interface process (shared by the drive
interface's live tests)."""

from __future__ import annotations

import math
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from ros_test_tools import call, probe_node, running, wait_until
from std_msgs.msg import Header
from std_srvs.srv import Trigger

from feeder_ros.msg import DriveCommand, DriveState
from feeder_ros.srv import SetDrive, SetTargetSpeed

BIN = Path(sys.executable).parent
DRIVE = str(BIN / "drive_interface")
SIMULATOR = str(BIN / "platform_simulator")
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
NODE = "drive_interface"


def stamp_s(header: Header) -> float:
    return Time.from_msg(header.stamp).nanoseconds * 1e-9


class Cell:
    """A probe acting as the cell controller for the drive interface in ``namespace``."""

    def __init__(self, probe: Node, namespace: str, listen: bool = True) -> None:
        self.probe = probe
        self.ns = namespace
        self.commands: list[DriveCommand] = []
        self.states: list[DriveState] = []
        self.diagnostics: list[DiagnosticArray] = []
        self._lock = threading.Lock()
        if listen:
            self.listen_to_commands()
        probe.create_subscription(DriveState, f"{namespace}/drive/state", self._state, RELIABLE)
        probe.create_subscription(DiagnosticArray, "/diagnostics", self._diagnostic, RELIABLE)
        self._heartbeat_pub = probe.create_publisher(Header, f"{namespace}/heartbeat", 10)
        self.beating = False
        self.last_beat_s = math.nan
        probe.create_timer(0.1, self._beat)

    def listen_to_commands(self) -> None:
        """Subscribe to drive/command (as the platform simulator does)."""
        self.probe.create_subscription(
            DriveCommand, f"{self.ns}/drive/command", self._command, RELIABLE
        )

    def _command(self, message: DriveCommand) -> None:
        with self._lock:
            self.commands.append(message)

    def _state(self, message: DriveState) -> None:
        with self._lock:
            self.states.append(message)

    def _diagnostic(self, message: DiagnosticArray) -> None:
        if any(s.name.startswith(f"{self.ns}/{NODE}") for s in message.status):
            with self._lock:
                self.diagnostics.append(message)

    def _beat(self) -> None:
        if self.beating:
            header = Header()
            header.stamp = self.probe.get_clock().now().to_msg()
            self._heartbeat_pub.publish(header)
            self.last_beat_s = stamp_s(header)

    # -- helpers used by the tests --------------------------------------------------------------
    def start_heartbeat(self) -> None:
        """Beat at 10 Hz; returns once the node is subscribed and a few beats went out."""
        assert wait_until(lambda: self._heartbeat_pub.get_subscription_count() > 0, 10.0)
        self.beating = True
        time.sleep(0.35)

    def commands_since(self, t_s: float) -> list[DriveCommand]:
        with self._lock:
            return [c for c in self.commands if stamp_s(c.header) >= t_s]

    def states_since(self, t_s: float) -> list[DriveState]:
        with self._lock:
            return [s for s in self.states if stamp_s(s.header) >= t_s]

    def last_state(self) -> DriveState | None:
        with self._lock:
            return self.states[-1] if self.states else None

    def wait_state(self, state: int, timeout_s: float = 15.0) -> DriveState:
        def reached() -> bool:
            last = self.last_state()
            return last is not None and last.state == state

        assert wait_until(reached, timeout_s), f"never reached state {state}: {self.last_state()}"
        last = self.last_state()
        assert last is not None
        return last

    def last_diagnostic(self) -> DiagnosticStatus | None:
        with self._lock:
            if not self.diagnostics:
                return None
            return self.diagnostics[-1].status[0]

    def now_s(self) -> float:
        return float(self.probe.get_clock().now().nanoseconds) * 1e-9

    def transition(self, transition_id: int) -> bool:
        answer = call(
            self.probe,
            ChangeState,
            f"{self.ns}/{NODE}/change_state",
            ChangeState.Request(transition=Transition(id=transition_id)),
            timeout_s=60.0,  # configure may compute the speed table
        )
        return bool(answer.success)

    def lifecycle_state(self) -> str:
        answer = call(self.probe, GetState, f"{self.ns}/{NODE}/get_state", GetState.Request())
        return str(answer.current_state.label)

    def trigger(self, name: str) -> Trigger.Response:
        return call(self.probe, Trigger, f"{self.ns}/{name}", Trigger.Request())

    def set_drive(self, frequency: float, amplitude: float, ramp: float) -> SetDrive.Response:
        request = SetDrive.Request(
            frequency_hz=frequency, amplitude_percent=amplitude, ramp_time_s=ramp
        )
        return call(self.probe, SetDrive, f"{self.ns}/set_drive", request)

    def set_parameter(self, name: str, value: ParameterValue) -> Any:
        request = SetParameters.Request(parameters=[ParameterMsg(name=name, value=value)])
        return call(self.probe, SetParameters, f"{self.ns}/{NODE}/set_parameters", request)

    def set_speed(self, speed: float, ramp: float = 0.0) -> SetTargetSpeed.Response:
        request = SetTargetSpeed.Request(speed_mps=speed, ramp_time_s=ramp)
        return call(self.probe, SetTargetSpeed, f"{self.ns}/set_target_speed", request)

    def bring_up(self) -> None:
        assert self.transition(Transition.TRANSITION_CONFIGURE)
        assert self.transition(Transition.TRANSITION_ACTIVATE)
        assert self.lifecycle_state() == "active"


@contextmanager
def drive_node(
    namespace: str, *params: str, params_file: Path | None = None, listen: bool = True
) -> Iterator[Cell]:
    command = [DRIVE, "--ros-args", "-r", f"__ns:={namespace}"]
    if params_file is not None:
        command += ["--params-file", str(params_file)]
    for param in params:
        command += ["-p", param]
    with running(command) as process, probe_node() as probe:
        cell = Cell(probe, namespace, listen)
        visible = wait_until(
            lambda: (NODE, namespace) in probe.get_node_names_and_namespaces(), 30.0
        )
        assert visible, process.poll()
        yield cell


def small_speed_table(cache_dir: Path) -> tuple[str, ...]:
    """Parameters for a coarse physics speed table, cached in ``cache_dir`` (fast to build)."""
    return (
        f"speed_model_cache_dir:={cache_dir}",
        "speed_model_frequency_steps:=12",
        "speed_model_amplitude_steps:=6",
        "speed_model_duration_s:=1.0",
    )
