"""An emulated feeder controller on Modbus TCP (pymodbus server in a thread), for tests and benches.

It speaks the :class:`~feeder_ros.drive.modbus.RegisterMap` protocol: what is written to the
command registers is mirrored to the status registers (running, actual frequency and amplitude),
an alarm can be raised from outside (running drops, alarm bit and code set) and is cleared by the
alarm-reset bit of the command word. :meth:`stop` and :meth:`start` take the server away and back
on the same port, which a client sees as a lost link and a reconnect.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import threading
from typing import Any

from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from feeder_ros.drive.modbus import COMMAND_ENABLE, COMMAND_RESET_ALARM, RegisterMap

__all__ = ["ControllerEmulator", "free_port"]

REGISTER_COUNT = 128


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


class ControllerEmulator:
    """``with ControllerEmulator(port) as controller:`` a controller on 127.0.0.1:port."""

    def __init__(self, port: int, register_map: RegisterMap | None = None) -> None:
        self.port = port
        self.map = register_map or RegisterMap()
        self._lock = threading.Lock()
        self._registers = [0] * REGISTER_COUNT
        self._pending_alarm: int | None = None
        self.writes: list[dict[int, int]] = []  # every command write, as {address: value}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: ModbusTcpServer | None = None
        self._thread: threading.Thread | None = None
        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)

    # -- control from the test ------------------------------------------------------------------
    def raise_alarm(self, code: int) -> None:
        """Alarm at the controller (e.g. coil over-temperature): it stops and reports ``code``."""
        with self._lock:
            self._pending_alarm = code
            self._apply_alarm()

    def register(self, address: int) -> int:
        with self._lock:
            return self._registers[address]

    def commands(self) -> list[dict[int, int]]:
        with self._lock:
            return list(self.writes)

    def _apply_alarm(self) -> None:
        if self._pending_alarm is None:
            return
        m, r = self.map, self._registers
        r[m.alarm_code] = self._pending_alarm
        r[m.status] = 1 << m.status_alarm_bit
        r[m.actual_amplitude] = 0

    # -- the server -----------------------------------------------------------------------------
    async def _action(
        self,
        function_code: int,
        start_address: int,
        address: int,
        count: int,
        registers: list[int],
        values: list[int] | list[bool] | None,
    ) -> None:
        with self._lock:
            if values is None:  # a read: answer from the shared copy
                registers[:] = self._registers
                return
            written = {address + i: int(v) for i, v in enumerate(values)}
            for a, v in written.items():
                self._registers[a - start_address] = v
            self.writes.append(written)
            m, r = self.map, self._registers
            if m.command in written:
                word = r[m.command]
                if word & COMMAND_RESET_ALARM:
                    self._pending_alarm = None
                    r[m.alarm_code] = 0
                alarm = self._pending_alarm is not None
                running = bool(word & COMMAND_ENABLE) and not alarm
                r[m.status] = (running << m.status_running_bit) | (alarm << m.status_alarm_bit)
                r[m.actual_frequency] = r[m.frequency]
                r[m.actual_amplitude] = r[m.amplitude] if running else 0
                self._apply_alarm()
            registers[:] = self._registers

    def start(self) -> None:
        ready = threading.Event()
        failure: list[BaseException] = []

        async def main() -> None:
            device = SimDevice(
                id=1,
                simdata=[SimData(0, count=REGISTER_COUNT, values=0, datatype=DataType.REGISTERS)],
                action=self._action,
            )
            self._server = ModbusTcpServer(device, address=("127.0.0.1", self.port))
            await self._server.serve_forever(background=True)  # listening when it returns
            ready.set()
            await self._server.serving

        def serve() -> None:
            loop = asyncio.new_event_loop()
            self._loop = loop
            try:
                loop.run_until_complete(main())
            except BaseException as error:  # reported by start() in the caller's thread
                failure.append(error)
            finally:
                ready.set()
                loop.close()

        self._thread = threading.Thread(target=serve, name="modbus_emulator", daemon=True)
        self._thread.start()
        if not ready.wait(10.0) or failure:
            raise RuntimeError(f"Modbus emulator did not start on port {self.port}: {failure}")

    def stop(self) -> None:
        """Close the listening socket and every connection (clients see the link drop)."""
        loop, server, thread = self._loop, self._server, self._thread
        if loop is None or server is None or thread is None:
            return
        shutdown: Any = server.shutdown  # untyped in pymodbus
        future = asyncio.run_coroutine_threadsafe(shutdown(), loop)
        future.result(timeout=10.0)
        thread.join(timeout=10.0)
        self._loop = self._server = self._thread = None

    def __enter__(self) -> ControllerEmulator:
        self.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()
