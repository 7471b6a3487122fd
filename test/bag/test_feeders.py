"""Several feeders in one bag (``feeder record`` of a cell under ``/``): told apart by namespace and
analysed each on its own, with the right speeds; a bag of one feeder as before.

The bag is written here with two synthetic feeders whose parts move at 5 and 8 mm/s, stamped on
one clock and interleaved message by message (as one recorder receives them); every expected value
follows from what was written. rosbags reads the same bag as an independent check of the counts.
"""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path
from typing import Any

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader as RosbagsReader
from sensor_msgs.msg import Imu

from feeder_ros.bag import BagWriter
from feeder_ros.bag.analysis import AnalysisError, analyze_bag, analyze_feeders
from feeder_ros.bag.feeders import FEEDER_TOPICS, feeder_namespace, group_feeders
from feeder_ros.cli.main import main
from feeder_ros.msg import (
    CarrierState,
    DriveCommand,
    PartExit,
    PartSensorEvent,
    PartState,
    PartStateArray,
    VehicleEstimate,
)

T0 = 1_760_000_000_000_000_000
MS = 1_000_000
S = 1_000_000_000

# per feeder: drive plan [(start ms, end ms, Hz, N)], part speed [m/s], transits [(enter, arrive)
# ms] between sensors 5 mm apart, exits
FEEDERS: dict[str, dict[str, Any]] = {
    "/feeder_a": {
        "plan": [(0, 1500, 30.0, 20.0), (1500, 3000, 33.0, 20.0)],
        "speed": 0.005,
        "transits": [(200, 1200), (1700, 2700)],  # 5 mm in 1 s: 5 mm/s
        "exits": 3,
    },
    "/feeder_b": {
        "plan": [(0, 3000, 40.0, 25.0)],
        "speed": 0.008,
        "transits": [(200, 825), (1000, 1625), (2000, 2625)],  # 5 mm in 0.625 s: 8 mm/s
        "exits": 6,
    },
}
SENSORS_M = (0.050, 0.055)


def stamp(message: Any, t_ns: int) -> Any:
    message.header.stamp.sec = t_ns // S
    message.header.stamp.nanosec = t_ns % S
    return message


def setting(plan: list[tuple[int, int, float, float]], k: int) -> tuple[float, float]:
    return next((f, a) for lo, hi, f, a in plan if lo <= k < hi)


def write_two_feeders(path: Path) -> dict[str, int]:
    """3 s of the two FEEDERS, every feeder topic at its rate, plus IMU and shared diagnostics;
    returns the messages written per topic."""
    written: dict[str, int] = {}
    with BagWriter(path, chunk_size=16 << 10) as w:
        relative = {
            "carrier/state": CarrierState,
            "drive/command": DriveCommand,
            "estimate": VehicleEstimate,
            "parts/state": PartStateArray,
            "parts/sensor_events": PartSensorEvent,
            "parts/exit": PartExit,
            "imu": Imu,
        }
        for ns in FEEDERS:
            for name in relative:
                w.add_topic(f"{ns}/{name}", FEEDER_TOPICS[name])
        w.add_topic("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray")

        def put(topic: str, message: Any, t_ns: int) -> None:
            w.write(topic, bytes(serialize_message(stamp(message, t_ns))), t_ns + 50_000)
            written[topic] = written.get(topic, 0) + 1

        events = {
            ns: sorted(
                (t, sensor, part)
                for part, times in enumerate(spec["transits"], start=1)
                for sensor, t in enumerate(times)
            )
            for ns, spec in FEEDERS.items()
        }
        for k in range(3000):
            t_ns = T0 + k * MS
            for ns, spec in FEEDERS.items():
                freq, amp = setting(spec["plan"], k)
                put(
                    f"{ns}/carrier/state",
                    CarrierState(drive_frequency_hz=freq, drive_amplitude_n=amp),
                    t_ns,
                )
                put(f"{ns}/imu", Imu(), t_ns)
                if k % 10 == 0:
                    command = DriveCommand(enabled=True, frequency_hz=freq, amplitude_n=amp)
                    put(f"{ns}/drive/command", command, t_ns)
                    put(f"{ns}/estimate", VehicleEstimate(mean_speed_mps=spec["speed"]), t_ns)
                    parts = PartStateArray()
                    parts.parts = [
                        PartState(
                            part_id=i,
                            position_m=spec["speed"] * k * 1e-3,  # moving at its speed
                            velocity_mps=spec["speed"],
                            on_track=True,
                        )
                        for i in (1, 2)
                    ]
                    put(f"{ns}/parts/state", parts, t_ns)
                if k % 400 == 100 and k // 400 < spec["exits"]:
                    put(f"{ns}/parts/exit", PartExit(part_id=k // 400 + 1), t_ns)
                for when, sensor, part in events[ns]:
                    if when == k:  # the same part ids in both feeders: each numbers its own
                        event = PartSensorEvent(
                            sensor_index=sensor,
                            sensor_position_m=SENSORS_M[sensor],
                            part_id=part,
                            present=True,
                        )
                        put(f"{ns}/parts/sensor_events", event, t_ns)
            if k % 1000 == 0:
                array = DiagnosticArray()
                warn = DiagnosticStatus.WARN if k >= 1000 else DiagnosticStatus.OK
                array.status = [
                    DiagnosticStatus(level=warn, name="/feeder_a/drive_interface: drive"),
                    DiagnosticStatus(name="/feeder_b/drive_interface: drive"),
                    DiagnosticStatus(name="cell: power"),
                ]
                put("/diagnostics", array, t_ns)
    return written


@pytest.fixture(scope="module")
def two_feeder_bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, int]]:
    path = tmp_path_factory.mktemp("cell") / "bag"
    return path, write_two_feeders(path)


def test_namespaces_are_found_from_the_feeder_topic_names() -> None:
    assert feeder_namespace("/feeder_a/carrier/state") == "/feeder_a"
    assert feeder_namespace("/cell/feeder_2/parts/sensor_events") == "/cell/feeder_2"
    assert feeder_namespace("/carrier/state") == "/"
    assert feeder_namespace("/feeder_a/imu/batch") == "/feeder_a"
    assert feeder_namespace("/chatter") is None
    assert feeder_namespace("/a/estimate", "std_msgs/msg/String") is None  # not the feeder's type
    cs = "feeder_ros/msg/CarrierState"
    groups = group_feeders(
        {
            "/feeder_a/carrier/state": cs,
            "/feeder_b/carrier/state": cs,
            "/feeder_b/remapped/state": cs,  # a remapped name: the namespace holding it
            "/elsewhere/state": cs,  # no feeder namespace holds it
        }
    )
    assert groups.namespaces == ["/feeder_a", "/feeder_b"]
    assert groups.routes["/feeder_b/remapped/state"] == "/feeder_b"
    assert groups.unassigned == ("/elsewhere/state",)
    # one feeder: every topic of a feeder type is its own, whatever its name
    one = group_feeders({"/f/carrier/state": cs, "/exit": "feeder_ros/msg/PartExit"})
    assert one.routes == {"/f/carrier/state": "/f", "/exit": "/f"}
    # no name tells: one feeder, in the namespace the topics share
    assert group_feeders({"/x/a": cs, "/x/b": cs}).routes == {"/x/a": "/x", "/x/b": "/x"}


def test_feeder_topics_are_the_nodes_declared_topics() -> None:
    """The relative names and types the analysis groups by are those the nodes declare."""
    from feeder_ros.nodes.catalog import node_interfaces

    declared = {
        spec.name: spec.type
        for interface in node_interfaces()
        for spec in (*interface.publishes, *interface.subscribes)
        if not spec.name.startswith("/")
    }
    assert dict(FEEDER_TOPICS) == declared


def test_each_feeder_is_analysed_on_its_own(two_feeder_bag: tuple[Path, dict[str, int]]) -> None:
    path, written = two_feeder_bag
    results = analyze_feeders(path)
    assert [r.namespace for r in results] == ["/feeder_a", "/feeder_b"]
    for result in results:
        spec = FEEDERS[result.namespace or ""]
        assert result.ok
        assert result.feeders == ["/feeder_a", "/feeder_b"]
        assert result.drive_source == "carrier state"
        settings = [(lo / 1000, f, a) for lo, _, f, a in spec["plan"]]
        assert [(s.start_s, s.frequency_hz, s.amplitude_n) for s in result.segments] == settings
        for segment in result.segments:
            for value in (
                segment.speed_ground_truth_mps,
                segment.speed_estimate_mps,
                segment.speed_sensors_mps,
            ):
                assert value == pytest.approx(spec["speed"], rel=1e-9)
        assert sum(s.transits for s in result.segments) == len(spec["transits"])
        assert sum(s.parts_exited for s in result.segments) == spec["exits"]
        assert result.totals()["speed_mps"] == pytest.approx(spec["speed"], rel=1e-9)
        # every drive sample of its own: none is out of order, no topic shared
        assert not any(
            p.startswith(("[out_of_order]", "[several_topics]")) for p in result.problems
        )
        ns = result.namespace
        assert result.messages == {
            t: written[f"{ns}/{name}"]
            for name, t in FEEDER_TOPICS.items()
            if f"{ns}/{name}" in written and name != "imu"
        }
        assert not result.data_lost
        assert result.loss is not None
        assert (result.loss.lost, result.loss.recorded) == (0, sum(written.values()))
    a, b = results
    # diagnostics: a status named after a feeder's node is that feeder's, another one both's
    assert [(d.t_s, d.name, d.level_name) for d in a.diagnostics] == [
        (0.0, "/feeder_a/drive_interface: drive", "OK"),
        (0.0, "cell: power", "OK"),
        (1.0, "/feeder_a/drive_interface: drive", "WARN"),
    ]
    assert [d.name for d in b.diagnostics] == ["/feeder_b/drive_interface: drive", "cell: power"]
    with RosbagsReader(path) as reader:  # an independent reader counts the same messages
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts == written
    for result in results:
        ns = result.namespace
        assert sum(result.messages.values()) == sum(
            n for t, n in counts.items() if t.startswith(f"{ns}/") and not t.endswith("/imu")
        )


def test_one_feeder_is_picked_by_namespace(two_feeder_bag: tuple[Path, dict[str, int]]) -> None:
    path, _ = two_feeder_bag
    with pytest.raises(AnalysisError, match=r"2 feeders in one bag \(/feeder_a, /feeder_b\)"):
        analyze_bag(path)
    b = analyze_bag(path, namespace="feeder_b/")  # normalised to /feeder_b
    assert b.namespace == "/feeder_b"
    assert b.name == "bag_feeder_b"
    assert [s.speed_ground_truth_mps for s in b.segments] == pytest.approx([0.008], rel=1e-9)
    with pytest.raises(
        AnalysisError, match=r"no feeder under namespace /feeder_c \(feeders found: /feeder_a, "
    ):
        analyze_feeders(path, namespace="/feeder_c")


def test_cli_analyze_and_info_show_each_feeder(
    two_feeder_bag: tuple[Path, dict[str, int]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path, _ = two_feeder_bag
    out = tmp_path / "out"
    assert main(["analyze", str(path), "--output", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"{path} [/feeder_a]: 2.999 s, drive from carrier state, 2 segment(s)" in text
    assert f"{path} [/feeder_b]: 2.999 s, drive from carrier state, 1 segment(s)" in text
    for slug, speed in (("feeder_a", 5.0), ("feeder_b", 8.0)):
        with (out / f"bag_{slug}_segments.csv").open() as f:
            rows = list(csv.DictReader(f))
        assert [float(r["speed_mm_s"]) for r in rows] == pytest.approx([speed] * len(rows))
        assert (out / f"bag_{slug}_segments.png").is_file()
    with (out / "comparison.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [(r["namespace"], r["status"]) for r in rows] == [
        ("/feeder_a", "ok"),
        ("/feeder_b", "ok"),
    ]
    assert [float(r["speed_mm_s"]) for r in rows] == pytest.approx([5.0, 8.0])
    document = json.loads((out / "analysis.json").read_text())
    assert [b["namespace"] for b in document["bags"]] == ["/feeder_a", "/feeder_b"]
    page = (out / "report.html").read_text()
    assert f"<h2>{path} [/feeder_a]</h2>" in page

    picked = tmp_path / "picked"
    assert main(["analyze", str(path), "--namespace", "/feeder_b", "--output", str(picked)]) == 0
    text = capsys.readouterr().out
    assert "[/feeder_b]" in text
    assert "[/feeder_a]" not in text
    assert sorted(p.name for p in picked.glob("*_segments.csv")) == ["bag_feeder_b_segments.csv"]
    assert main(["analyze", str(path), "--namespace", "/nope"]) == 2
    assert "no feeder under namespace /nope" in capsys.readouterr().err

    assert main(["info", str(path)]) == 0
    assert "Feeders:   2 (/feeder_a, /feeder_b)" in capsys.readouterr().out


def test_a_truncated_two_feeder_bag_says_each_feeders_loss(
    two_feeder_bag: tuple[Path, dict[str, int]], tmp_path: Path
) -> None:
    """The loss is the bag's: every feeder's section says it, with that feeder's share."""
    path, written = two_feeder_bag
    copy = tmp_path / "bag"
    shutil.copytree(path, copy)
    mcap = copy / "bag_0.mcap"
    mcap.write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 2])
    results = analyze_feeders(copy)
    assert [r.namespace for r in results] == ["/feeder_a", "/feeder_b"]
    loss = results[0].loss
    assert loss is not None
    assert loss.recorded == sum(written.values())
    assert 0 < loss.lost < loss.recorded
    shares = []
    for result in results:
        assert result.data_lost
        assert result.loss is loss
        lost, recorded = result.feeder_loss()
        ns = result.namespace
        assert recorded == sum(n for t, n in written.items() if t.startswith(f"{ns}/"))
        assert result.loss_summary().startswith(
            f"{loss.lost} of {loss.recorded} recorded messages lost ({lost} of {recorded} of this "
            "feeder's)"
        )
        shares.append(lost)
    diagnostics = next(t for t in loss.topics if t.topic == "/diagnostics")
    assert sum(shares) + diagnostics.lost == loss.lost  # /diagnostics is no feeder's own
