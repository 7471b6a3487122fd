"""Modbus TCP backend for a real feeder controller: register map, scaling, and the I/O thread.

The register map (holding registers, 16-bit unsigned) and its scaling come from ROS parameters
(``config/drive_interface.yaml``). Each poll writes the command block (command word, frequency,
amplitude, ramp time, a heartbeat counter the controller can watch) and reads the status block
(status word with running/alarm bits, alarm code, actual frequency and amplitude).

All I/O runs in one background thread, so :meth:`ModbusTcpBackend.write` never blocks the node:
a lost link is reported through :meth:`ModbusTcpBackend.status` as a fault, and the thread keeps
reconnecting with exponential back-off (``reconnect_min_s`` doubling up to ``reconnect_max_s``).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ModbusException

from feeder_ros.drive.backend import BackendStatus, DriveOutput

__all__ = ["ModbusSettings", "ModbusTcpBackend", "RegisterMap", "StatusWord", "contiguous_runs"]

COMMAND_ENABLE = 1 << 0  # command word: drive on
COMMAND_RESET_ALARM = 1 << 1  # command word: acknowledge the controller's alarm


@dataclass(frozen=True)
class RegisterMap:
    """Addresses (0-based holding registers) and scaling (counts per unit)."""

    command: int = 0
    frequency: int = 1
    amplitude: int = 2
    ramp_time: int = 3
    heartbeat: int = 4
    status: int = 10
    alarm_code: int = 11
    actual_frequency: int = 12
    actual_amplitude: int = 13
    frequency_counts_per_hz: float = 10.0
    amplitude_counts_per_percent: float = 100.0
    ramp_time_counts_per_s: float = 1000.0
    status_running_bit: int = 0
    status_alarm_bit: int = 1

    def __post_init__(self) -> None:
        addresses = self.command_addresses() + self.status_addresses()
        if len(set(addresses)) != len(addresses) or min(addresses) < 0 or max(addresses) > 65535:
            raise ValueError(f"register addresses must be distinct and in 0..65535: {addresses}")
        for name in (
            "frequency_counts_per_hz",
            "amplitude_counts_per_percent",
            "ramp_time_counts_per_s",
        ):
            value = getattr(self, name)
            if not math.isfinite(value) or value <= 0.0:
                raise ValueError(f"{name}={value!r} must be > 0")
        for name in ("status_running_bit", "status_alarm_bit"):
            if not 0 <= getattr(self, name) <= 15:
                raise ValueError(f"{name}={getattr(self, name)} must be a bit 0..15")
        if max(self.status_addresses()) - min(self.status_addresses()) >= 125:
            raise ValueError("status registers must lie within 125 registers (one read)")

    def command_addresses(self) -> list[int]:
        return [self.command, self.frequency, self.amplitude, self.ramp_time, self.heartbeat]

    def status_addresses(self) -> list[int]:
        return [self.status, self.alarm_code, self.actual_frequency, self.actual_amplitude]

    def encode(
        self, output: DriveOutput, heartbeat: int, reset_alarm: bool = False
    ) -> dict[int, int]:
        """The command registers for ``output``; values outside 16 bits raise ValueError."""
        word = (COMMAND_ENABLE if output.enabled else 0) | (
            COMMAND_RESET_ALARM if reset_alarm else 0
        )
        amplitude = output.amplitude_percent if output.enabled else 0.0
        return {
            self.command: word,
            self.frequency: _counts(
                "frequency_hz", output.frequency_hz, self.frequency_counts_per_hz
            ),
            self.amplitude: _counts(
                "amplitude_percent", amplitude, self.amplitude_counts_per_percent
            ),
            self.ramp_time: _counts("ramp_time_s", output.ramp_time_s, self.ramp_time_counts_per_s),
            self.heartbeat: heartbeat & 0xFFFF,
        }

    def decode_status(self, registers: Mapping[int, int]) -> StatusWord:
        word = registers[self.status]
        return StatusWord(
            running=bool(word >> self.status_running_bit & 1),
            alarm=bool(word >> self.status_alarm_bit & 1),
            alarm_code=registers[self.alarm_code],
            actual_frequency_hz=registers[self.actual_frequency] / self.frequency_counts_per_hz,
            actual_amplitude_percent=registers[self.actual_amplitude]
            / self.amplitude_counts_per_percent,
        )


@dataclass(frozen=True)
class StatusWord:
    running: bool
    alarm: bool
    alarm_code: int
    actual_frequency_hz: float
    actual_amplitude_percent: float


def _counts(name: str, value: float, scale: float) -> int:
    counts = round(value * scale)
    if not math.isfinite(value) or not 0 <= counts <= 0xFFFF:
        raise ValueError(
            f"{name}={value!r} does not fit a 16-bit register at {scale:g} counts/unit"
        )
    return int(counts)


def contiguous_runs(registers: Mapping[int, int]) -> list[tuple[int, list[int]]]:
    """``{address: value}`` as (start, values) runs of consecutive addresses (one write each)."""
    runs: list[tuple[int, list[int]]] = []
    for address in sorted(registers):
        if runs and runs[-1][0] + len(runs[-1][1]) == address:
            runs[-1][1].append(registers[address])
        else:
            runs.append((address, [registers[address]]))
    return runs


@dataclass(frozen=True)
class ModbusSettings:
    host: str = "127.0.0.1"
    port: int = 502
    device_id: int = 1
    timeout_s: float = 0.5
    poll_period_s: float = 0.05
    reconnect_min_s: float = 0.2
    reconnect_max_s: float = 5.0
    command_timeout_s: float = 0.5  # no write() from the node this long: drive off (stale)


class ModbusTcpBackend:
    """``ModbusTcpBackend(settings, register_map)``: the DriveBackend of a Modbus TCP controller."""

    name = "modbus_tcp"

    def __init__(self, settings: ModbusSettings, register_map: RegisterMap) -> None:
        self.settings = settings
        self.map = register_map
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._output = DriveOutput(False, 0.0, 0.0, 0.0)
        self._written_s = time.monotonic()
        self._reset_alarm = False
        self._status = BackendStatus(connected=False, fault="not connected yet")
        self._heartbeat = 0
        self._reconnects = 0
        self._errors = 0
        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)  # we report link state ourselves

    # -- DriveBackend --------------------------------------------------------------------------
    def connect(self) -> None:
        if self._thread is not None:
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="modbus_tcp", daemon=True)
        self._thread.start()

    def write(self, output: DriveOutput) -> None:
        with self._lock:
            switching_off = self._output.enabled and not output.enabled
            self._output = output
            self._written_s = time.monotonic()
        if switching_off:
            self._wake.set()  # an e-stop or fault goes out now, not at the next poll

    def acknowledge_fault(self) -> None:
        """Pulse the alarm-reset bit on the next write (the controller decides if it clears)."""
        with self._lock:
            self._reset_alarm = True
        self._wake.set()

    def status(self) -> BackendStatus:
        with self._lock:
            return self._status

    def disconnect(self) -> None:
        """Stop the I/O thread; it writes drive-off before closing the link if it can."""
        thread = self._thread
        if thread is None:
            return
        with self._lock:
            self._output = DriveOutput(False, self._output.frequency_hz, 0.0, 0.0)
        self._stop.set()
        self._wake.set()
        thread.join(timeout=5.0 + 2 * self.settings.timeout_s)
        self._thread = None
        with self._lock:
            self._status = BackendStatus(connected=False, fault="disconnected")

    # -- the I/O thread ------------------------------------------------------------------------
    def _set_status(self, status: BackendStatus) -> None:
        with self._lock:
            self._status = status

    def _details(self) -> dict[str, str]:
        s = self.settings
        return {
            "endpoint": f"{s.host}:{s.port} device {s.device_id}",
            "reconnects": str(self._reconnects),
            "errors": str(self._errors),
        }

    def _run(self) -> None:
        s = self.settings
        delay = s.reconnect_min_s
        client: Any = None
        while True:
            if client is None:
                client = ModbusTcpClient(s.host, port=s.port, timeout=s.timeout_s, retries=0)
                if not client.connect():
                    client.close()
                    client = None
                    self._errors += 1
                    reason = f"cannot connect to {s.host}:{s.port}; retry in {delay:.2f} s"
                    self._set_status(BackendStatus(False, fault=reason, details=self._details()))
                    if self._stop.wait(delay):
                        return
                    delay = min(2.0 * delay, s.reconnect_max_s)
                    continue
                self._reconnects += 1
            stopping = self._stop.is_set()
            try:
                self._exchange(client)
                delay = s.reconnect_min_s
            except (ModbusException, OSError) as error:  # a lost or refusing link
                self._errors += 1
                client.close()
                client = None
                reason = f"link to {s.host}:{s.port} lost ({error}); retry in {delay:.2f} s"
                self._set_status(BackendStatus(False, fault=reason, details=self._details()))
                if stopping or self._stop.wait(delay):
                    return
                delay = min(2.0 * delay, s.reconnect_max_s)
                continue
            if stopping:
                client.close()
                return
            self._wake.wait(s.poll_period_s)
            self._wake.clear()

    def _exchange(self, client: Any) -> None:
        with self._lock:
            output, reset = self._output, self._reset_alarm
            self._reset_alarm = False
            age = time.monotonic() - self._written_s
        encode_fault = ""
        if output.enabled and age > self.settings.command_timeout_s:
            # the node stopped handing over fresh outputs (hung or gone): never replay a stale one
            encode_fault = f"stale command: none from the node for {age:.2f} s; drive off"
            output = DriveOutput(False, output.frequency_hz, 0.0, 0.0)
        self._heartbeat = (self._heartbeat + 1) & 0xFFFF
        device = self.settings.device_id
        try:
            registers = self.map.encode(output, self._heartbeat, reset)
        except ValueError as error:  # never send what the registers cannot hold: drive off
            encode_fault = f"command not representable: {error}"
            registers = self.map.encode(DriveOutput(False, 0.0, 0.0, 0.0), self._heartbeat, reset)
        if encode_fault:  # said before the drive is switched off, never after
            with self._lock:
                self._status = replace(self._status, fault=encode_fault)
        for start, values in contiguous_runs(registers):
            response = client.write_registers(start, values, device_id=device)
            if response.isError():
                raise ConnectionError(f"write at {start} refused: {response}")
        addresses = self.map.status_addresses()
        first = min(addresses)
        response = client.read_holding_registers(
            first, count=max(addresses) - first + 1, device_id=device
        )
        if response.isError():
            raise ConnectionError(f"status read at {first} refused: {response}")
        status = self.map.decode_status(
            {first + i: int(v) for i, v in enumerate(response.registers)}
        )
        details = self._details()
        details.update(
            {
                "controller running": str(status.running),
                "alarm code": str(status.alarm_code),
                "heartbeat counter": str(self._heartbeat),
                "last poll (monotonic s)": f"{time.monotonic():.3f}",
            }
        )
        alarm = f"controller alarm (code {status.alarm_code})" if status.alarm else ""
        fault = "; ".join(text for text in (encode_fault, alarm) if text)
        self._set_status(
            BackendStatus(
                connected=True,
                fault=fault,
                actual_frequency_hz=status.actual_frequency_hz,
                actual_amplitude_percent=status.actual_amplitude_percent,
                details=details,
            )
        )
