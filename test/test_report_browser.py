"""``feeder analyze``'s report as a production engineer opens it: written by the real command,
rendered by a real browser (headless chromium) 1280 px wide. Nothing may stick out of the page,
and the headline figures the browser shows must be the bag's, counted here from its messages
with rosbags (an independent reader)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from bag.run_bag import EXPECTED, write_run_bag
from browser import layout
from rclpy.serialization import deserialize_message
from rosbags.rosbag2 import Reader

from feeder_ros.msg import DriveState

FEEDER = str(Path(sys.executable).parent / "feeder")


def _from_the_bag(bag: Path) -> dict[str, float]:
    """Parts fed, run time and the (one) fault's duration, read from the bag's messages."""
    stamps: list[int] = []
    exits = 0
    fault: list[int] = []  # its first stamp, then the first stamp after it
    with Reader(bag) as reader:
        for connection, _, raw in reader.messages():
            if connection.topic == "/diagnostics":
                continue  # the run is the span of the feeder's own topics
            message = deserialize_message(raw, _type(connection.msgtype))
            t = message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec
            stamps.append(t)
            exits += connection.topic.endswith("/parts/exit")
            if connection.topic.endswith("/drive/state"):
                in_fault = message.state == DriveState.STATE_FAULT
                if (in_fault and not fault) or (not in_fault and len(fault) == 1):
                    fault.append(t)
    return {
        "parts": exits,
        "run_s": (max(stamps) - min(stamps)) * 1e-9,
        "fault_s": (fault[1] - fault[0]) * 1e-9,
    }


def _type(name: str) -> type:
    from importlib import import_module

    package, _, message = name.split("/")
    return getattr(import_module(f"{package}.msg"), message)  # type: ignore[no-any-return]


def test_the_report_fits_1280_px_and_shows_the_bags_figures(tmp_path: Path) -> None:
    write_run_bag(tmp_path / "bag")
    out = tmp_path / "report"
    result = subprocess.run(
        [FEEDER, "analyze", str(tmp_path / "bag"), "--output", str(out)],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    rendered = layout(out / "report.html", width=1280)
    assert rendered["width"] == 1280
    assert rendered["over"] == []
    assert rendered["scroll_width"] <= 1280
    assert rendered["tables"] == ["segments", "faults", "frequency_response", "diagnostics"]
    assert len(rendered["images"]) == 1  # speed and drive over time
    assert all(done and natural > 0 and 0 < shown <= 1280 for done, natural, shown in
               rendered["images"])  # fmt: skip

    truth = _from_the_bag(tmp_path / "bag")
    assert truth["parts"] == EXPECTED["parts"]
    headline = rendered["headline"]
    assert headline["parts_fed"] == str(truth["parts"])
    minutes, seconds = divmod(round(truth["run_s"]), 60)
    assert headline["run_time"] == f"{minutes} min {seconds:02d} s"
    assert headline["feed_rate"] == f"{truth['parts'] / (truth['run_s'] / 60):.1f} /min"
    assert headline["faults"] == f"1 ({truth['fault_s']:.1f} s)"
    share = EXPECTED["at_target_s"] / EXPECTED["target_s"]
    assert headline["time_at_target"].startswith(f"{100 * share:.0f} %")
    # the terminal says the same (one formatting layer)
    for value in headline.values():
        assert value in result.stdout


def test_the_layout_probe_sees_a_page_that_is_too_wide(tmp_path: Path) -> None:
    """The check above can fail: a 1500 px wide table is reported."""
    page = tmp_path / "wide.html"
    page.write_text(
        "<!DOCTYPE html><html><body><table data-table='wide' style='width:1500px'><tr><td>x</td>"
        "</tr></table></body></html>"
    )
    rendered = layout(page, width=1280)
    assert rendered["scroll_width"] > 1280
    assert any(line.startswith("TABLE.") for line in rendered["over"])
