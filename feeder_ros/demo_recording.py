"""The demo's bag and report: ``feeder record`` of the demo feeder while the controller drives it,
then ``feeder analyze``'s report of that bag, what a production engineer gets of a shift.

The recorder is its own process (as in a cell), started once the cell is up and stopped with
Ctrl-C (SIGINT) after the cell stopped; it records the feeder's topics except the accelerometer
(the report does not use it, and it is most of a bag) and ``/diagnostics``. Its output goes to
``record.log`` beside the bag. A recorder or an analysis that fails is said, not hidden: the
demo's verdict is the cell's, the report a product of it.
"""

from __future__ import annotations

import shutil
import signal
import subprocess
from pathlib import Path

from feeder_ros.bag.analysis import analyze_feeders
from feeder_ros.bag.errors import BagError
from feeder_ros.bag.presentation import sections
from feeder_ros.bag.report import write_outputs

__all__ = ["TOPICS", "finish", "start"]

#: relative to the feeder's namespace, but /diagnostics
TOPICS = (
    "drive/command",
    "drive/state",
    "estimate",
    "calibration",
    "carrier/state_batch",
    "parts/state",
    "parts/sensor_events",
    "parts/exit",
    "speed/status",
    "/diagnostics",
)
STOP_LIMIT_S = 30.0


def start(bin_dir: Path, namespace: str, output: Path) -> subprocess.Popen[bytes]:
    """``feeder record`` of the demo feeder into ``output/bag`` (an earlier run's is replaced)."""
    bag = output / "bag"
    if bag.exists():
        shutil.rmtree(bag)
    with (output / "record.log").open("wb") as log:
        return subprocess.Popen(
            [str(bin_dir / "feeder"), "record", "--namespace", namespace, "-o", str(bag),
             *TOPICS],
            stdout=log, stderr=subprocess.STDOUT,
        )  # fmt: skip


def finish(recorder: subprocess.Popen[bytes], namespace: str, output: Path) -> str:
    """Stop the recorder, analyse its bag into ``output/report``; a line for the summary."""
    recorder.send_signal(signal.SIGINT)
    try:
        code = recorder.wait(timeout=STOP_LIMIT_S)
    except subprocess.TimeoutExpired:
        recorder.kill()
        code = recorder.wait()
        return f"report: none (the recorder did not stop within {STOP_LIMIT_S:g} s; killed)"
    if code != 0:
        return f"report: none (the recorder ended with status {code}; see {output / 'record.log'})"
    try:
        results = analyze_feeders(output / "bag", namespace=namespace)
    except BagError as error:
        return f"report: none (the bag cannot be analysed: {error})"
    write_outputs(results, output / "report")
    facts = ", ".join(f"{f.label} {f.value}" for s in sections(results) for f in s.headline)
    return f"report: {output / 'report' / 'report.html'} ({facts})"
