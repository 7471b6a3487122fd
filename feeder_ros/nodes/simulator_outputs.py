"""The platform simulator's sensor and ground-truth topics: the physics core's sample arrays in,
messages out.

- the accelerometer: ``imu`` (one ``sensor_msgs/Imu`` per sample, the noise variance on the
  covariance diagonal, no orientation or gyroscope) or, with ``publish_batches``, ``imu/batch``;
- the carrier's state: ``carrier/state`` per sample or ``carrier/state_batch``;
- the part-present sensors' edges: ``parts/sensor_events``;
- every part's state: ``parts/state`` (the parts on the track, and each exited part once);
- parts leaving the feeder: ``parts/exit``, with the running total.

:class:`SimulatorOutputs` owns those publishers and the little state they need (the parts already
reported as exited, the exit count); :mod:`feeder_ros.nodes.platform_simulator` calls it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time as TimeMsg
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu

from feeder_ros.msg import (
    AccelerometerBatch,
    CarrierState,
    CarrierStateBatch,
    PartExit,
    PartSensorEvent,
    PartState,
    PartStateArray,
)
from feeder_ros.physics.simulation import Phase
from feeder_ros.physics.track_end import TrackEndQueue
from feeder_ros.sensors.part_presence import SensorEdge

# sensor data: best effort and volatile like qos_profile_sensor_data, but with a history deep
# enough for a tick's burst (at 1 kHz and 10 ms ticks, 10 samples leave at once): with
# qos_profile_sensor_data's depth of 5 the writer itself overwrote samples before sending them
SENSOR_QOS = QoSProfile(
    depth=100,
    history=HistoryPolicy.KEEP_LAST,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)
# ground truth and events: reliable, with a second of history at 1 kHz for slow readers
STATE_QOS = QoSProfile(
    depth=1000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE
)


class SimulatorOutputs:
    """The publishers of the simulator's samples and events; ``stamp`` turns a simulated time
    into a message stamp."""

    def __init__(self, node: Node, batches: bool, stamp: Callable[[float], TimeMsg]) -> None:
        pub = node.create_publisher
        self._batches = batches
        self._stamp = stamp
        if batches:
            self._imu_pub = pub(AccelerometerBatch, "imu/batch", SENSOR_QOS)
            self._state_pub = pub(CarrierStateBatch, "carrier/state_batch", STATE_QOS)
        else:
            self._imu_pub = pub(Imu, "imu", SENSOR_QOS)
            self._state_pub = pub(CarrierState, "carrier/state", STATE_QOS)
        self._parts_pub = pub(PartStateArray, "parts/state", STATE_QOS)
        self._sensor_pub = pub(PartSensorEvent, "parts/sensor_events", STATE_QOS)
        self._exit_pub = pub(PartExit, "parts/exit", STATE_QOS)
        self.parts_out = 0  # parts that have left the feeder
        self._exit_listed = np.zeros(0, bool)  # exited parts already sent once on parts/state

    def restart(self, count: int) -> None:
        """A new simulation with ``count`` parts: no part out, none listed as exited."""
        self.parts_out = 0
        self._exit_listed = np.zeros(count, bool)

    def imu(
        self, t: np.ndarray, measured: np.ndarray, frame_id: str, period_s: float, sigma: float
    ) -> None:
        """Accelerometer samples ``measured`` (n x 3, m/s^2) at times ``t``, noise ``sigma``."""
        if self._batches:
            batch = AccelerometerBatch()
            batch.header.stamp = self._stamp(float(t[0]))
            batch.header.frame_id = frame_id
            batch.sample_period_s = period_s
            batch.acceleration_x_mps2 = measured[:, 0].tolist()
            batch.acceleration_y_mps2 = measured[:, 1].tolist()
            batch.acceleration_z_mps2 = measured[:, 2].tolist()
            batch.noise_stddev_mps2 = sigma
            self._imu_pub.publish(batch)
            return
        message = Imu()  # reused: publish() serialises at once
        message.header.frame_id = frame_id
        message.orientation_covariance[0] = -1.0  # no orientation estimate
        message.angular_velocity_covariance[0] = -1.0  # no gyroscope
        for k in (0, 4, 8):
            message.linear_acceleration_covariance[k] = sigma**2
        acceleration = message.linear_acceleration
        for j, (x, y, z) in enumerate(measured.tolist()):
            message.header.stamp = self._stamp(float(t[j]))
            acceleration.x, acceleration.y, acceleration.z = x, y, z
            self._imu_pub.publish(message)

    def states(self, t: np.ndarray, columns: dict[str, np.ndarray], period_s: float) -> None:
        """The carrier's state at times ``t``: ``columns`` by message field name."""
        if self._batches:
            batch = CarrierStateBatch()
            batch.header.stamp = self._stamp(float(t[0]))
            batch.header.frame_id = "carrier"
            batch.sample_period_s = period_s
            for name, values in columns.items():
                setattr(batch, name, values.tolist())
            self._state_pub.publish(batch)
            return
        message = CarrierState()  # reused: publish() serialises at once
        message.header.frame_id = "carrier"
        rows = zip(*(values.tolist() for values in columns.values()), strict=True)
        names = list(columns)
        for j, row in enumerate(rows):
            message.header.stamp = self._stamp(float(t[j]))
            for name, value in zip(names, row, strict=True):
                setattr(message, name, value)
            self._state_pub.publish(message)

    def sensor_edges(self, edges: Iterable[SensorEdge]) -> None:
        for edge in edges:
            event = PartSensorEvent()
            event.header.stamp = self._stamp(edge.t_s)
            event.sensor_index = edge.sensor_index
            event.sensor_position_m = edge.position_m
            event.part_id = edge.part
            event.present = edge.present
            self._sensor_pub.publish(event)

    def parts(
        self, t: float, result: Any, row: int, track: np.ndarray, queue: TrackEndQueue | None
    ) -> None:
        """Every part's state at sample ``row`` of ``result`` (time ``t``; ``track``: positions
        on the track, nan once exited; ``queue``: the stopper's queue, if any)."""
        message = PartStateArray()
        message.header.stamp = self._stamp(t)
        message.header.frame_id = "track"
        carrier_v = float(result.carrier_v_mps[row])
        phases = result.part_phase[row]
        exited = np.isnan(track)  # left the core, and not queued at a stopper
        queued = np.zeros(phases.size, bool) if queue is None else queue.queued_at(t, phases.size)
        # the parts on the track, and each exited part once (on_track false): the message stays
        # the size of the track's load however many parts have passed (listing every part ever
        # fed grew it by a part per feed interval, and its cost with it, in every subscriber)
        if self._exit_listed.size < phases.size:
            self._exit_listed = np.concatenate(
                (self._exit_listed, np.zeros(phases.size - self._exit_listed.size, bool))
            )
        listed = np.flatnonzero(~exited | ~self._exit_listed[: phases.size])
        self._exit_listed[: phases.size] |= exited
        for i in listed.tolist():
            phase = int(phases[i])
            part = PartState()
            part.part_id = int(i)
            part.on_track = not exited[i]
            if part.on_track:  # a queued part stands still on the carrier
                part.position_m = float(track[i])
                part.velocity_mps = carrier_v if queued[i] else float(result.part_v_mps[row, i])
                part.relative_velocity_mps = part.velocity_mps - carrier_v
                part.phase = Phase.STICK if queued[i] else phase
            else:
                part.position_m = math.nan
                part.velocity_mps = math.nan
                part.relative_velocity_mps = math.nan
            message.parts.append(part)
        self._parts_pub.publish(message)

    def exits(self, times: np.ndarray, parts: Any) -> None:
        """Parts ``parts`` leaving the feeder at ``times``."""
        for t, part in zip(times, parts, strict=True):
            self.parts_out += 1
            message = PartExit()
            message.header.stamp = self._stamp(float(t))
            message.part_id = int(part)
            message.parts_out_total = self.parts_out
            self._exit_pub.publish(message)
