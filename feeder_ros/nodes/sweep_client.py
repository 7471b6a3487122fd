"""The live source of ``feeder identify``: a speed sweep on a running cell, simulated or real.

Everything goes through the public interface of the feeder's namespace, so the same sweep runs on
the platform simulator and on a real feeder behind the drive interface's Modbus backend:

* the drive interface's lifecycle (brought to *active* when asked: configure, activate), its
  ``set_drive`` service for each point, ``start`` once, ``stop`` at the end, and a ``heartbeat``
  at 5 Hz for its watchdog; ``drive/state`` tells when the ramp reached the point's setting and
  which force the drive applies (``amplitude_n``);
* the measurement, one of:

  - ``sensors``: part-present sensor edges (``parts/sensor_events``, rising edges of one part at
    the first and the second sensor, the paper's timing over 8.5 cm): the mean speed of the
    transits that began after the settle time and ended within the window (the point's
    ``duration_s`` is then their mean transit time). In distance mode the distance is the
    sensors' spacing (it must match the plan's ``distance_m``) and a point ends with its first
    complete transit;
  - ``monitor``: the speed monitor's ``speed/status`` estimated speed (the sensorless estimator's
    window mean), averaged over the window (distance mode: integrated until the distance is
    covered); the estimator's own window should fit in the settle time;
  - ``truth``: the simulator's ``parts/state`` (ground truth; simulator only): the mean advance of
    the parts on the track over the window divided by its length.

One part mass per live sweep (the parts on the track are what they are). Per point:
``set_drive`` (refused: the point is kept as not ok with the drive's reason; clamped:
the applied values are recorded), wait until ``drive/state`` is RUNNING at the set point, wait
``settle_s`` on the node clock (simulated time works), then measure. The drive is stopped at the
end, on errors and on Ctrl-C (rclpy's signal handlers are not installed, so the context is still
up to send the stop; if even that fails, the heartbeat stops and the drive's watchdog ramps the
drive to zero). The measured points go to the caller (``measured``) before the client's node is
torn down, also those of a sweep cut short by an error or Ctrl-C; a teardown that hangs in the
middleware ends the process after ``runner.TEARDOWN_LIMIT_S`` with status 1 and the stacks on
stderr, the points already saved.

The meters are :mod:`feeder_ros.identification.live_meters` (ROS-free).
"""

from __future__ import annotations

import faulthandler
import math
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import rclpy
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rcl_interfaces.srv import GetParameters
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Header
from std_srvs.srv import Trigger

from feeder_ros.identification.live_meters import (
    Measurement,
    StatusMeter,
    TransitMeter,
    TruthMeter,
)
from feeder_ros.identification.sweep import SweepPlan, SweepPoint, SweepResult
from feeder_ros.msg import DriveState, PartSensorEvent, PartStateArray, SpeedStatus
from feeder_ros.nodes import runner
from feeder_ros.nodes.ros_time import clock_seconds, stamp_seconds
from feeder_ros.nodes.service_calls import ServiceCallError, call_service
from feeder_ros.srv import SetDrive

__all__ = [
    "MEASURES",
    "LiveSweepError",
    "SweepClient",
    "check_live_plan",
    "run_live_sweep",
]

MEASURES = ("sensors", "monitor", "truth")
HEARTBEAT_PERIOD_S = 0.2
DRIVE_NODE = "drive_interface"
#: a point's setting counts as reached when drive/state is within this of it
SETTING_TOLERANCE = 1e-6
#: wall-clock limit on reaching a setting (ramps are limited by the drive's rates)
REACH_TIMEOUT_S = 60.0
#: after a window ends, wait up to this long (wall) for messages stamped inside it still on the way
LATE_MESSAGES_S = 2.0
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)

Progress = Callable[[int, int], None]
Log = Callable[[str], None]


#: the drive interface's services a request may be sent to twice (the second finds the drive
#: where the first left it)
REPEATABLE = frozenset({"get_state", "get_parameters", "start", "stop"})


class LiveSweepError(RuntimeError):
    """The live sweep cannot go on (no drive interface, a fault, a refused start, ...)."""


# ------------------------------------------------------------------------------------ client


class SweepClient:
    """A node in the feeder's namespace that runs a sweep through the drive interface."""

    def __init__(self, node: Node, measure: str, log: Log, manage_lifecycle: bool = True) -> None:
        if measure not in MEASURES:
            raise ValueError(f"measure={measure!r} is not one of {', '.join(MEASURES)}")
        self.node = node
        self.measure = measure
        self.log = log
        self.manage_lifecycle = manage_lifecycle
        self.transits = TransitMeter()
        self.status = StatusMeter()
        self.truth = TruthMeter()
        self._state_lock = threading.Lock()
        self._state: DriveState | None = None
        self._beating = False
        self._commanded = False  # set_drive was called: stop() has something to stop
        #: the points measured so far (all of them once :meth:`run` returns), in plan order
        self.points: list[SweepPoint] = []
        self._scale = math.nan  # the drive's full-scale force of the running sweep [N]
        self._heartbeat = node.create_publisher(Header, "heartbeat", 10)
        node.create_timer(HEARTBEAT_PERIOD_S, self._beat)
        node.create_subscription(DriveState, "drive/state", self._on_state, RELIABLE)
        self._measure_topic = {
            "sensors": "parts/sensor_events",
            "monitor": "speed/status",
            "truth": "parts/state",
        }[measure]
        if measure == "sensors":
            node.create_subscription(PartSensorEvent, self._measure_topic, self._on_edge, RELIABLE)
        elif measure == "monitor":
            node.create_subscription(SpeedStatus, self._measure_topic, self._on_status, RELIABLE)
        else:
            node.create_subscription(PartStateArray, self._measure_topic, self._on_parts, RELIABLE)
        self._services: dict[str, Any] = {
            "set_drive": node.create_client(SetDrive, "set_drive"),
            "start": node.create_client(Trigger, "start"),
            "stop": node.create_client(Trigger, "stop"),
            "get_state": node.create_client(GetState, f"{DRIVE_NODE}/get_state"),
            "change_state": node.create_client(ChangeState, f"{DRIVE_NODE}/change_state"),
            "get_parameters": node.create_client(GetParameters, f"{DRIVE_NODE}/get_parameters"),
        }

    # -- callbacks (executor thread) ---------------------------------------------------------------
    def _beat(self) -> None:
        if self._beating:
            header = Header()
            header.stamp = self.node.get_clock().now().to_msg()
            self._heartbeat.publish(header)

    def _on_state(self, message: DriveState) -> None:
        with self._state_lock:
            self._state = message

    def _on_edge(self, message: PartSensorEvent) -> None:
        part = None if message.part_id == PartSensorEvent.PART_ID_UNKNOWN else int(message.part_id)
        self.transits.add(
            stamp_seconds(message.header.stamp),
            int(message.sensor_index),
            float(message.sensor_position_m),
            part,
            bool(message.present),
        )

    def _on_status(self, message: SpeedStatus) -> None:
        self.status.add(stamp_seconds(message.header.stamp), float(message.estimated_speed_mps))

    def _on_parts(self, message: PartStateArray) -> None:
        self.truth.add(
            stamp_seconds(message.header.stamp),
            {int(p.part_id): float(p.position_m) for p in message.parts if p.on_track},
        )

    # -- helpers (main thread) ---------------------------------------------------------------------
    def now_s(self) -> float:
        return clock_seconds(self.node.get_clock())

    def state(self) -> DriveState | None:
        with self._state_lock:
            return self._state

    def _name(self, relative: str) -> str:
        ns = self.node.get_namespace().rstrip("/")
        return f"{ns}/{relative}"

    def call(self, name: str, request: Any, timeout_s: float = 10.0) -> Any:
        """The service's answer; a lost answer to a request of :data:`REPEATABLE` is asked
        again (:func:`feeder_ros.nodes.service_calls.call_service`)."""
        ask_again_s = min(5.0, timeout_s / 2.0) if name in REPEATABLE else None

        def asking_again() -> None:
            self.log(f"no answer from {name} after {ask_again_s:g} s: asking again")

        try:
            return call_service(self._services[name], request, timeout_s, ask_again_s, asking_again)
        except ServiceCallError as error:
            raise LiveSweepError(str(error)) from error

    def _check_fault(self) -> None:
        state = self.state()
        if state is not None and state.state in (DriveState.STATE_FAULT, DriveState.STATE_ESTOP):
            kind = "fault" if state.state == DriveState.STATE_FAULT else "emergency stop"
            raise LiveSweepError(f"drive interface {kind}: {state.fault_reason}")

    def _wait(self, condition: Callable[[], bool], timeout_s: float, what: str) -> None:
        deadline = time.monotonic() + timeout_s
        while not condition():
            self._check_fault()
            if time.monotonic() > deadline:
                raise LiveSweepError(f"timed out after {timeout_s:g} s waiting for {what}")
            time.sleep(0.01)

    def sleep_until(self, t_s: float, wall_limit_s: float) -> None:
        """Wait until the node clock reads ``t_s`` (sim time too), watching for drive faults."""
        self._wait(lambda: self.now_s() >= t_s, wall_limit_s, f"node time {t_s:.3f} s")

    # -- set-up ------------------------------------------------------------------------------------
    def prepare(self) -> float | None:
        """Check the drive interface and the measurement topic, bring the drive to active (when
        managing the lifecycle), start the heartbeat; returns its full scale [N] if readable."""
        set_drive = self._services["set_drive"]
        if not set_drive.wait_for_service(timeout_sec=15.0):
            raise LiveSweepError(
                f"no drive interface in namespace {self.node.get_namespace()!r}: service "
                f"{set_drive.service_name} not found (is the cell running? --namespace?)"
            )
        if self.manage_lifecycle:
            self._activate()
        topic = self._name(self._measure_topic)
        if not self._wait_publisher(topic, 10.0):
            raise LiveSweepError(
                f"nobody publishes {topic}: --measure {self.measure} needs "
                + {
                    "sensors": "part-present sensors (platform simulator or the cell's sensors)",
                    "monitor": "a speed monitor (and the vehicle estimator feeding it)",
                    "truth": "the platform simulator's ground truth",
                }[self.measure]
            )
        full_scale = self._full_scale()
        self._beating = True
        self._wait(
            lambda: self._heartbeat.get_subscription_count() > 0, 10.0, "the heartbeat subscriber"
        )
        self._wait(lambda: self.state() is not None, 10.0, "drive/state")
        time.sleep(3 * HEARTBEAT_PERIOD_S)
        self._check_fault()
        return full_scale

    def _wait_publisher(self, topic: str, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.node.count_publishers(topic) > 0:
                return True
            time.sleep(0.05)
        return False

    def _activate(self) -> None:
        label = self.call("get_state", GetState.Request()).current_state.label
        if label == "unconfigured":
            self.log("configuring the drive interface")
            answer = self.call(
                "change_state",
                ChangeState.Request(transition=Transition(id=Transition.TRANSITION_CONFIGURE)),
                timeout_s=300.0,  # it may compute its speed table
            )
            if not answer.success:
                raise LiveSweepError("the drive interface refused to configure (see its log)")
            label = "inactive"
        if label == "inactive":
            self.log("activating the drive interface")
            answer = self.call(
                "change_state",
                ChangeState.Request(transition=Transition(id=Transition.TRANSITION_ACTIVATE)),
            )
            if not answer.success:
                raise LiveSweepError("the drive interface refused to activate (see its log)")
        elif label != "active":
            raise LiveSweepError(f"the drive interface is {label!r}; it cannot be activated")

    def _full_scale(self) -> float | None:
        try:
            answer = self.call(
                "get_parameters", GetParameters.Request(names=["full_scale_force_n"]), 5.0
            )
        except LiveSweepError:
            return None
        if len(answer.values) == 1 and answer.values[0].type == 3:  # PARAMETER_DOUBLE
            return float(answer.values[0].double_value)
        return None

    # -- the sweep ---------------------------------------------------------------------------------
    def run(self, plan: SweepPlan, progress: Progress | None = None) -> SweepResult:
        check_live_plan(plan)
        full_scale = self.prepare()
        if full_scale is not None and not math.isclose(full_scale, plan.full_scale_force_n):
            self.log(
                f"the drive's full_scale_force_n is {full_scale:g} N (the plan says "
                f"{plan.full_scale_force_n:g} N): forces are the drive's"
            )
        scale = full_scale if full_scale is not None else plan.full_scale_force_n
        self._scale = scale
        self.points = []
        total = plan.point_count
        for mass, amplitude, frequency in plan.settings():
            self.points.append(self.point(plan, frequency, amplitude, mass, scale))
            if progress is not None:
                progress(len(self.points), total)
        return self.result()

    def result(self) -> SweepResult:
        """The points measured so far as a result (an interrupted sweep's are worth keeping)."""
        return SweepResult(tuple(self.points), f"live {self.node.get_namespace()}", self._scale)

    def point(
        self, plan: SweepPlan, frequency: float, amplitude: float, mass: float, scale: float
    ) -> SweepPoint:
        def failed(reason: str, f: float = frequency, a: float = amplitude) -> SweepPoint:
            return SweepPoint(f, a, a / 100.0 * scale, mass, math.nan, 0.0, ok=False, reason=reason)

        self._commanded = True
        answer = self.call(
            "set_drive",
            SetDrive.Request(
                frequency_hz=frequency, amplitude_percent=amplitude, ramp_time_s=plan.ramp_time_s
            ),
        )
        if answer.result == SetDrive.Response.REFUSED:
            self.log(f"{frequency:g} Hz, {amplitude:g} %: refused: {answer.reason}")
            return failed(f"refused by the drive interface: {answer.reason}")
        f_set, a_set = float(answer.frequency_hz), float(answer.amplitude_percent)
        if answer.result == SetDrive.Response.CLAMPED:
            self.log(f"{frequency:g} Hz, {amplitude:g} %: clamped: {answer.reason}")
        state = self.state()
        if state is None or state.state not in (
            DriveState.STATE_RUNNING,
            DriveState.STATE_RAMPING,
        ):
            started = self.call("start", Trigger.Request())
            if not started.success:
                raise LiveSweepError(f"the drive interface refused to start: {started.message}")

        def reached() -> bool:
            s = self.state()
            return (
                s is not None
                and s.state == DriveState.STATE_RUNNING
                and abs(s.frequency_hz - f_set) <= SETTING_TOLERANCE * max(1.0, f_set)
                and abs(s.amplitude_percent - a_set) <= SETTING_TOLERANCE * 100.0
            )

        self._wait(reached, REACH_TIMEOUT_S + 2.0 * plan.ramp_time_s, f"{f_set:g} Hz, {a_set:g} %")
        reached_state = self.state()
        assert reached_state is not None
        force = float(reached_state.amplitude_n)
        t0 = self.now_s() + plan.settle_s
        self.sleep_until(t0, 30.0 + 5.0 * plan.settle_s)
        measurement, reason = self._measure(plan, t0)
        ok = measurement.ok and not reason
        if not ok and not reason:
            reason = self._no_data_reason(plan)
        return SweepPoint(
            frequency_hz=f_set,
            amplitude_percent=a_set,
            amplitude_n=force,
            part_mass_kg=mass,
            speed_mps=measurement.speed_mps,
            duration_s=measurement.duration_s,
            ok=ok,
            reason=reason,
        )

    def _measure(self, plan: SweepPlan, t0: float) -> tuple[Measurement, str]:
        if plan.window_s is not None:
            t1 = t0 + plan.window_s
            self.sleep_until(t1, 30.0 + 5.0 * plan.window_s)
            self._catch_up(t1)
            meters: dict[str, Callable[[float, float], Measurement]] = {
                "sensors": self.transits.measure,
                "monitor": self.status.measure,
                "truth": self.truth.measure,
            }
            return meters[self.measure](t0, t1), ""
        distance = plan.distance_m
        assert distance is not None
        limit = t0 + plan.max_window_s
        result: Measurement | None = None

        def covered() -> bool:
            nonlocal result
            now = self.now_s()
            if self.measure == "sensors":
                result = self.transits.first_transit(t0)
            else:
                meter = self.status.covered if self.measure == "monitor" else self.truth.measure
                candidate = meter(t0, now)
                result = candidate if candidate.covered_m >= distance else None
            return result is not None or now >= limit

        self._wait(covered, 30.0 + 5.0 * plan.max_window_s, f"{distance:g} m of travel")
        if result is None:
            return Measurement(math.nan, plan.max_window_s, 0), (
                f"no part travelled {distance:g} m within max_window_s={plan.max_window_s:g} s"
            )
        if self.measure == "sensors" and abs(result.covered_m - distance) > 1e-3:
            return result, (
                f"the sensors are {result.covered_m:g} m apart but the plan's distance is "
                f"{distance:g} m"
            )
        return result, ""

    def _catch_up(self, t1: float) -> None:
        """Wait (at most LATE_MESSAGES_S of wall time) for a measurement message stamped at or
        after ``t1``: a source running behind the node clock (a loaded simulator, a slow link)
        still has the window's last messages on the way."""
        latest: dict[str, Callable[[], float]] = {
            "sensors": lambda: self.transits.latest_s,
            "monitor": lambda: self.status.latest_s,
            "truth": lambda: self.truth.latest_s,
        }
        deadline = time.monotonic() + LATE_MESSAGES_S
        while latest[self.measure]() < t1 and time.monotonic() < deadline:
            time.sleep(0.01)

    def _no_data_reason(self, plan: SweepPlan) -> str:
        window = f"the {plan.window_s:g} s window"
        if self.measure == "sensors":
            return (
                f"no part passed both sensors within {window} (feed parts, or lengthen --window "
                "or use --distance)"
            )
        if self.measure == "monitor":
            return f"no finite estimated speed on speed/status within {window}"
        return f"no part stayed on the track through {window}"

    def stop(self) -> None:
        """Ramp the drive to zero; keep the heartbeat going until it is off (or 10 s)."""
        if not self._commanded:
            self._beating = False
            return  # the sweep never touched the drive
        try:
            answer = self.call("stop", Trigger.Request(), timeout_s=5.0)
            if not answer.success:
                self.log(f"stop: {answer.message}")
            deadline = time.monotonic() + 10.0
            while time.monotonic() < deadline:
                state = self.state()
                if state is None or state.state not in (
                    DriveState.STATE_RAMPING,
                    DriveState.STATE_RUNNING,
                ):
                    break  # idle (ramped to zero), or a latched fault: the output is off
                time.sleep(0.02)
        except LiveSweepError as error:
            self.log(f"could not stop the drive ({error}); its watchdog will, without heartbeat")
        finally:
            self._beating = False


def check_live_plan(plan: SweepPlan) -> None:
    """What a live sweep cannot do: change the parts between points."""
    if len(plan.part_masses_kg) > 1:
        raise LiveSweepError(
            f"{len(plan.part_masses_kg)} part masses: a live sweep measures the parts that are on "
            "the track; give one mass (--masses) and run one sweep per part mass"
        )


@contextmanager
def _spinning_node(namespace: str, use_sim_time: bool = False) -> Iterator[Node]:
    """A node in its own context (no signal handlers: Ctrl-C leaves it up to stop the drive),
    spun by a background thread; on the cell's ``/clock`` with ``use_sim_time``."""
    context = Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = rclpy.create_node(
            "sweep_client",
            namespace=namespace or "/",
            context=context,
            parameter_overrides=[Parameter("use_sim_time", value=use_sim_time)],
        )
    except Exception:
        rclpy.shutdown(context=context)
        raise
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    try:
        yield node
    finally:
        # the middleware's teardown can hang for good (see runner.TEARDOWN_LIMIT_S): bounded
        faulthandler.dump_traceback_later(runner.TEARDOWN_LIMIT_S, exit=True)
        try:
            executor.shutdown(timeout_sec=2.0)
            thread.join(timeout=5.0)
            node.destroy_node()
            rclpy.shutdown(context=context)
        finally:
            faulthandler.cancel_dump_traceback_later()


def run_live_sweep(
    plan: SweepPlan,
    namespace: str = "",
    measure: str = "sensors",
    manage_lifecycle: bool = True,
    progress: Progress | None = None,
    log: Log | None = None,
    use_sim_time: bool = False,
    measured: Callable[[SweepResult], None] | None = None,
) -> SweepResult:
    """Run ``plan`` on the cell in ``namespace`` (see the module docstring); the drive is stopped
    at the end, on errors and on Ctrl-C. ``use_sim_time``: settle and windows on the cell's
    ``/clock`` (a simulator running faster than real time), as the cell's nodes use it.
    ``measured`` gets the result once the drive is stopped and before the client's node is torn
    down (save it there: a teardown that hangs ends the process); on an error or Ctrl-C it gets
    the points measured until then, if any, and the error propagates."""
    say: Log = log or (lambda text: None)
    check_live_plan(plan)
    if namespace and not namespace.startswith("/"):
        namespace = "/" + namespace
    with _spinning_node(namespace, use_sim_time) as node:
        client = SweepClient(node, measure, say, manage_lifecycle)
        try:
            client.run(plan, progress)
        finally:
            try:
                client.stop()
            finally:
                if measured is not None and client.points:
                    measured(client.result())
        return client.result()
