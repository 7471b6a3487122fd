"""Ctrl-C and ``feeder``'s exit status, on real processes.

``feeder cell``, ``feeder record`` and ``feeder view`` run until stopped: Ctrl-C is their normal
end, exit status 0 once the nodes are stopped / the bag (readable) or the server is closed. A
command whose work Ctrl-C cuts short
(``feeder sim`` mid-run) exits 130. Ctrl-C is sent as a terminal sends it: SIGINT to the whole
process group (the command and the nodes it started). DDS is isolated by conftest (the session's
own ROS_DOMAIN_ID, discovery on localhost only), which every process here inherits.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from ros_test_tools import DrainedProcess, probe_node, wait_until
from simulator_process import manual_cell_file

from feeder_ros.bag import Bag, bag_info

BIN = Path(sys.executable).parent
FEEDER = str(BIN / "feeder")
NS = "/sig_cell/feeder_1"


def _one_feeder(tmp_path: Path) -> Path:
    return manual_cell_file(tmp_path / "cell.yaml", "sig_cell", [NS])


def _start(*args: str) -> DrainedProcess:
    # its own process group, as a terminal's foreground job: Ctrl-C signals the whole group
    return DrainedProcess([FEEDER, *args], start_new_session=True)


def _ctrl_c(process: DrainedProcess, timeout_s: float = 60.0) -> int:
    os.killpg(process.pid, signal.SIGINT)
    try:
        return process.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        raise AssertionError(f"did not stop on Ctrl-C:\n{process.output()[-3000:]}") from None


def _stop(process: DrainedProcess) -> None:
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()


def _children(pid: int) -> set[int]:
    result = subprocess.run(
        ["ps", "-o", "pid=", "--ppid", str(pid)], capture_output=True, text=True, check=False
    )
    return {int(line) for line in result.stdout.split()}


def _alive(pid: int) -> bool:
    stat = Path(f"/proc/{pid}/stat")
    try:
        return stat.read_text().split()[2] != "Z"
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return False


def test_ctrl_c_ends_a_recording_and_a_running_cell_with_exit_status_0(tmp_path: Path) -> None:
    bag = tmp_path / "run1"
    cell = _start("cell", "--config", str(_one_feeder(tmp_path)))
    recorder: DrainedProcess | None = None
    try:
        with probe_node() as node:

            def publishing() -> bool:
                topics = dict(node.get_topic_names_and_types())
                return f"{NS}/carrier/state" in topics and f"{NS}/drive/command" in topics

            assert wait_until(publishing, 60.0), cell.output()[-3000:]
        nodes = _children(cell.pid)
        assert len(nodes) == 2

        recorder = _start("record", "--namespace", NS, "-o", str(bag))
        assert wait_until(lambda: "recording into" in recorder.output(), 60.0), recorder.output()
        # discovery of the topics (every second), then seconds of data
        assert wait_until(lambda: f"recording {NS}/carrier/state" in recorder.output(), 30.0)
        time.sleep(3.0)
        assert _ctrl_c(recorder) == 0, recorder.output()[-3000:]
        output = recorder.output()
        assert "stopped by signal" in output
        assert "Traceback" not in output
        info = bag_info(Bag(bag), verify=True)  # closed: complete and readable
        assert not info.cut_short
        assert info.problems == []
        assert info.topics[f"{NS}/carrier/state"].message_count > 20
        assert not info.lost_data()

        assert _ctrl_c(cell) == 0, cell.output()[-3000:]
        output = cell.output()
        assert "[cell] stopping" in output
        assert "feeder: interrupted" not in output
        assert wait_until(lambda: not any(_alive(pid) for pid in nodes), 30.0)
    finally:
        _stop(cell)
        if recorder is not None:
            _stop(recorder)


def test_ctrl_c_while_a_composed_cell_starts_stops_it_with_exit_status_0(tmp_path: Path) -> None:
    # the cell's first line printed, its nodes' modules (rclpy, numba, ...) still loading: the
    # Ctrl-C stops the cell as it would once the nodes run
    cell = _start("cell", "--composed", "--config", str(_one_feeder(tmp_path)))
    try:
        assert wait_until(lambda: "[cell] sig_cell: 2 nodes" in cell.output(), 120.0), (
            cell.output()[-3000:]
        )
        assert _ctrl_c(cell) == 0, cell.output()[-3000:]
        output = cell.output()
        assert "[cell] stopped" in output
        assert "Traceback" not in output
        assert "feeder: interrupted" not in output
    finally:
        _stop(cell)


def test_ctrl_c_in_the_middle_of_a_simulation_is_exit_status_130(tmp_path: Path) -> None:
    out = tmp_path / "run.csv"
    # the logistic model's ODE solver: minutes for this run; the progress bar shows it started
    logistic = ["--set", "stiffness_model=logistic", "--set", "drive_amplitude_n=40"]
    command = [FEEDER, "sim", *logistic, "--duration", "2000", "--progress", "--output", str(out)]
    sim = subprocess.Popen(command, stderr=subprocess.PIPE, start_new_session=True)
    assert sim.stderr is not None
    stderr = b""
    try:
        # read as it comes: the bar is redrawn after a carriage return, with no newline
        os.set_blocking(sim.stderr.fileno(), False)
        deadline = time.monotonic() + 120.0
        while b"simulating   0%|" not in stderr and time.monotonic() < deadline:
            stderr += sim.stderr.read() or b""
            time.sleep(0.05)
        assert b"simulating   0%|" in stderr, stderr.decode()[-3000:]
        os.killpg(sim.pid, signal.SIGINT)
        os.set_blocking(sim.stderr.fileno(), True)
        stderr += sim.stderr.read()
        assert sim.wait(timeout=60) == 130, stderr.decode()[-3000:]
        text = stderr.decode()
        assert text.endswith("feeder: interrupted\n"), text[-3000:]
        assert "Traceback" not in text
        assert not out.exists()  # nothing half-written
    finally:
        if sim.poll() is None:
            os.killpg(sim.pid, signal.SIGKILL)
            sim.wait()
        sim.stderr.close()


def test_ctrl_c_ends_a_cell_and_its_live_view_with_exit_status_0(tmp_path: Path) -> None:
    # the terminal signals the whole group: the cell, its nodes and its `feeder view` at once
    cell = _start("cell", "--config", str(_one_feeder(tmp_path)), "--foxglove", "0")
    try:
        # the simulator constructed (its first log line) and the view serving: a Ctrl-C while a
        # node still imports is not what this test is about
        assert wait_until(
            lambda: "simulating f_n" in cell.output() and "serving the live view" in cell.output(),
            60.0,
        ), cell.output()[-3000:]
        children = _children(cell.pid)
        assert len(children) == 3  # two nodes and the view
        assert _ctrl_c(cell) == 0, cell.output()[-3000:]
        output = cell.output()
        assert "[cell] stopping" in output
        assert "stopped by signal" in output  # the view's summary
        assert "Traceback" not in output
        assert wait_until(lambda: not any(_alive(pid) for pid in children), 30.0)
    finally:
        _stop(cell)


def _interrupt_repeatedly(process: DrainedProcess, times: int = 3, gap_s: float = 0.02) -> int:
    """Ctrl-C, then SIGINT again every ``gap_s`` while it stops (as ``feeder cell`` sends one to
    its children right after the terminal's): the first stops it, the others land in its
    teardown. (A SIGINT once the process has printed its summary and exits ends it by the
    signal: Python restores the default action as it finalises.)"""
    for _ in range(times):
        if process.poll() is not None:
            break
        os.killpg(process.pid, signal.SIGINT)
        time.sleep(gap_s)
    try:
        return process.wait(timeout=60.0)
    except subprocess.TimeoutExpired:
        raise AssertionError(f"did not stop:\n{process.output()[-3000:]}") from None


def test_further_ctrl_c_while_a_view_or_a_recording_stops_do_not_cut_it_short(
    tmp_path: Path,
) -> None:
    """The summary is printed and the exit status is 0 however many SIGINTs follow the first
    (a view started by a cell got two and printed "feeder: interrupted" instead, exit 130)."""
    view = _start("view", "--namespace", NS, "--port", "0")
    recorder = _start("record", "--namespace", NS, "-o", str(tmp_path / "bag"))
    try:
        assert wait_until(lambda: "serving the live view" in view.output(), 60.0), view.output()
        assert wait_until(lambda: "recording into" in recorder.output(), 60.0), recorder.output()
        for process in (view, recorder):
            status = _interrupt_repeatedly(process)
            output = process.output()
            assert (status, "feeder: interrupted" in output) == (0, False), output[-3000:]
            assert "stopped by signal" in output
            assert "Traceback" not in output
        assert not bag_info(Bag(tmp_path / "bag"), verify=True).cut_short  # closed, readable
    finally:
        _stop(view)
        _stop(recorder)


def test_only_the_first_interrupt_raises_within_the_block() -> None:
    from feeder_ros.cli.interrupts import first_interrupt_stops

    before = signal.getsignal(signal.SIGINT)
    with first_interrupt_stops():
        pass
    assert signal.getsignal(signal.SIGINT) is before  # not interrupted: as it was
    raised = 0
    try:
        with first_interrupt_stops():
            for _ in range(3):
                try:
                    os.kill(os.getpid(), signal.SIGINT)
                    time.sleep(0.05)  # the handler runs between bytecodes of the main thread
                except KeyboardInterrupt:
                    raised += 1
        assert raised == 1
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN  # ending: ignored to the exit
    finally:
        signal.signal(signal.SIGINT, before)


CTRL_C_UNDER_RCLPY = """
import os, signal, sys, time
from rclpy.utilities import get_default_context
from feeder_ros import recording
from feeder_ros.cli.interrupts import first_interrupt_stops
from feeder_ros.ros_compat import RosSession

def down(context):
    deadline = time.monotonic() + 10.0
    while context.ok() and time.monotonic() < deadline:
        time.sleep(0.01)
    return not context.ok()

raised = 0
with first_interrupt_stops():
    with RosSession() as session:  # rclpy's signal handlers installed
        try:
            os.kill(os.getpid(), signal.SIGINT)
            print("context down:", down(session.context), flush=True)
        except KeyboardInterrupt:
            raised += 1
print("raised:", raised, flush=True)

# a Ctrl-C while forward() makes its node: the node meets a context rclpy has shut down
real = recording.TopicRecorder
def interrupted_recorder(*args):
    os.kill(os.getpid(), signal.SIGINT)
    down(get_default_context())
    return real(*args)
recording.TopicRecorder = interrupted_recorder

class Sink:
    closed = 0
    def close(self):
        Sink.closed += 1

summary = recording.Forwarded()
selection = recording.TopicSelection(namespace="/sig_forward")
with first_interrupt_stops():
    recording.forward(Sink(), selection, summary, ("sig_forward", "forwarding"))
print("stopped by:", summary.stopped_by, "sink closed:", Sink.closed > 0, flush=True)
"""


def test_under_rclpys_handlers_a_ctrl_c_stops_by_the_context_and_raises_nothing() -> None:
    """rclpy shuts the context down on a Ctrl-C; an exception raised from the handler as well
    landed, once, in rclpy's ``Task.__del__`` (swallowed, its traceback printed). A Ctrl-C in
    the moment ``forward`` makes its node is a stop too, not an error."""
    child = subprocess.run(
        [sys.executable, "-c", CTRL_C_UNDER_RCLPY], capture_output=True, text=True, timeout=120
    )
    assert child.returncode == 0, child.stderr[-3000:]
    assert child.stdout.splitlines() == [
        "context down: True",
        "raised: 0",
        "stopped by: signal sink closed: True",
    ], child.stderr[-3000:]
    assert "Traceback" not in child.stderr
