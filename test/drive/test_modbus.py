"""Modbus TCP backend: register map and scaling, then the real client against the loopback
emulator: commands on the wire, status read back, controller alarm, link loss and reconnect."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator

import pytest

from feeder_ros.drive.backend import DriveOutput
from feeder_ros.drive.modbus import (
    COMMAND_ENABLE,
    COMMAND_RESET_ALARM,
    ModbusSettings,
    ModbusTcpBackend,
    RegisterMap,
    contiguous_runs,
)
from feeder_ros.drive.modbus_emulator import ControllerEmulator, free_port


def wait_for(predicate: Callable[[], bool], timeout_s: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return predicate()


def test_encode_scales_into_registers_and_refuses_overflow() -> None:
    m = RegisterMap()
    registers = m.encode(DriveOutput(True, 29.6, 42.5, 42.5, 0.02), heartbeat=7)
    assert registers == {0: COMMAND_ENABLE, 1: 296, 2: 4250, 3: 20, 4: 7}
    off = m.encode(DriveOutput(False, 29.6, 42.5, 42.5), heartbeat=70000, reset_alarm=True)
    assert off == {0: COMMAND_RESET_ALARM, 1: 296, 2: 0, 3: 0, 4: 70000 & 0xFFFF}
    with pytest.raises(ValueError, match=r"frequency_hz=7000\.0 does not fit"):
        m.encode(DriveOutput(True, 7000.0, 1.0, 1.0), heartbeat=0)


def test_decode_status_bits_and_scaling() -> None:
    m = RegisterMap(status_running_bit=3, status_alarm_bit=5)
    status = m.decode_status({10: (1 << 3) | (1 << 5), 11: 12, 12: 300, 13: 2500})
    assert status.running
    assert status.alarm
    assert status.alarm_code == 12
    assert status.actual_frequency_hz == 30.0
    assert status.actual_amplitude_percent == 25.0


def test_register_map_validation() -> None:
    with pytest.raises(ValueError, match="distinct"):
        RegisterMap(frequency=0)
    with pytest.raises(ValueError, match=r"bit 0\.\.15"):
        RegisterMap(status_alarm_bit=16)
    assert contiguous_runs({4: 1, 0: 5, 1: 6, 10: 2}) == [(0, [5, 6]), (4, [1]), (10, [2])]


class Node:
    """Stands in for the drive interface node: hands the backend the same output every 20 ms."""

    def __init__(self, backend: ModbusTcpBackend) -> None:
        self.backend = backend
        self.output = DriveOutput(False, 0.0, 0.0, 0.0)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(0.02):
            self.backend.write(self.output)

    def close(self) -> None:
        self._stop.set()
        self._thread.join()


@pytest.fixture
def link() -> Iterator[tuple[ControllerEmulator, ModbusTcpBackend]]:
    port = free_port()
    emulator = ControllerEmulator(port)
    emulator.start()
    settings = ModbusSettings(
        port=port, timeout_s=2.0, poll_period_s=0.02, reconnect_min_s=0.05, reconnect_max_s=0.4
    )
    backend = ModbusTcpBackend(settings, RegisterMap())
    try:
        yield emulator, backend
    finally:
        backend.disconnect()
        emulator.stop()


def test_commands_reach_the_controller_and_status_comes_back(
    link: tuple[ControllerEmulator, ModbusTcpBackend],
) -> None:
    emulator, backend = link
    node = Node(backend)
    node.output = DriveOutput(True, 31.5, 40.0, 40.0, 0.02)
    backend.connect()
    assert wait_for(lambda: backend.status().actual_amplitude_percent == 40.0)
    status = backend.status()
    assert status.connected
    assert status.fault == ""
    assert status.actual_frequency_hz == 31.5
    assert status.details["controller running"] == "True"
    last = emulator.commands()[-1]
    assert (last[0], last[1], last[2], last[3]) == (COMMAND_ENABLE, 315, 4000, 20)
    beats = [c[4] for c in emulator.commands()]
    assert beats == sorted(beats)
    assert len(set(beats)) == len(beats)  # a fresh heartbeat counter each poll
    node.close()
    backend.disconnect()
    assert emulator.commands()[-1][0] == 0  # drive off written on the way out
    assert emulator.commands()[-1][2] == 0


def test_controller_alarm_is_a_fault_until_acknowledged(
    link: tuple[ControllerEmulator, ModbusTcpBackend],
) -> None:
    emulator, backend = link
    node = Node(backend)
    node.output = DriveOutput(True, 30.0, 20.0, 20.0)
    backend.connect()
    assert wait_for(lambda: backend.status().actual_amplitude_percent == 20.0)
    emulator.raise_alarm(17)
    assert wait_for(lambda: backend.status().fault == "controller alarm (code 17)")
    assert backend.status().actual_amplitude_percent == 0.0  # the controller stopped itself
    assert backend.status().connected
    backend.acknowledge_fault()
    assert wait_for(lambda: backend.status().fault == "")
    assert any(c[0] & COMMAND_RESET_ALARM for c in emulator.commands())
    node.close()


def test_link_loss_is_a_fault_and_reconnects_with_back_off(
    link: tuple[ControllerEmulator, ModbusTcpBackend],
) -> None:
    emulator, backend = link
    node = Node(backend)
    node.output = DriveOutput(True, 30.0, 20.0, 20.0)
    backend.connect()
    assert wait_for(lambda: backend.status().connected)
    emulator.stop()
    assert wait_for(lambda: not backend.status().connected)
    assert wait_for(lambda: "cannot connect to 127.0.0.1" in backend.status().fault)
    assert wait_for(lambda: "retry in 0.40 s" in backend.status().fault)  # doubled up to the max
    errors = int(backend.status().details["errors"])
    assert errors >= 3
    emulator.start()  # the controller is back on the same port
    assert wait_for(lambda: backend.status().connected and backend.status().fault == "")
    assert backend.status().details["reconnects"] == "2"
    assert wait_for(lambda: bool(emulator.commands()))
    assert emulator.commands()[-1][2] == 2000
    node.close()


def test_a_stale_output_is_never_replayed_to_the_controller(
    link: tuple[ControllerEmulator, ModbusTcpBackend],
) -> None:
    emulator, backend = link
    backend.settings = ModbusSettings(**{**backend.settings.__dict__, "command_timeout_s": 0.3})
    backend.write(DriveOutput(True, 30.0, 20.0, 20.0))
    backend.connect()
    assert wait_for(lambda: emulator.register(RegisterMap().amplitude) == 2000)
    # the node stops handing over outputs (hung): the thread switches the drive off itself
    assert wait_for(lambda: emulator.register(RegisterMap().amplitude) == 0)
    assert emulator.register(RegisterMap().command) == 0
    assert "stale command: none from the node for" in backend.status().fault
    backend.write(DriveOutput(True, 30.0, 25.0, 25.0))
    assert wait_for(lambda: emulator.register(RegisterMap().amplitude) == 2500)
