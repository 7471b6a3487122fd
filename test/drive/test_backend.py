"""The sim backend on its own: what it publishes, and its status with and without a listener."""

from __future__ import annotations

from feeder_ros.drive.backend import NO_SIMULATOR, DriveOutput, SimBackend


def test_sim_backend_warns_while_nothing_listens_and_publishes_a_stop_on_disconnect() -> None:
    sent: list[DriveOutput] = []
    listeners = [0]
    backend = SimBackend(sent.append, lambda: listeners[0])
    assert not backend.status().connected
    assert backend.status().warning == ""  # not connected: not yet talking to anyone
    backend.write(DriveOutput(True, 30.0, 10.0, 4.0, time_s=1.0))
    assert sent == []  # nothing goes out before connect

    backend.connect()
    status = backend.status()
    assert status.connected
    assert status.warning == NO_SIMULATOR
    assert status.details["drive/command subscribers"] == "0"
    output = DriveOutput(True, 30.0, 10.0, 4.0, time_s=2.0)
    backend.write(output)
    assert sent == [output]  # published all the same: a simulator that joins follows

    listeners[0] = 2
    status = backend.status()
    assert (status.connected, status.warning) == (True, "")
    assert status.details["drive/command subscribers"] == "2"
    assert status.details["last command"] == "enabled=True 30.000 Hz 10.00 %"

    backend.disconnect()
    assert sent[-1] == DriveOutput(False, 30.0, 0.0, 0.0, time_s=2.0)
    assert not backend.status().connected


def test_sim_backend_without_a_listener_count_never_warns() -> None:
    backend = SimBackend(lambda output: None)
    backend.connect()
    status = backend.status()
    assert (status.connected, status.warning) == (True, "")
    assert "drive/command subscribers" not in status.details
