"""``feeder record`` and ``feeder analyze`` as real processes.

The recorder records the installed ``platform_simulator`` in a namespace while a probe node listens
to the same topics and drives the simulator; the bag is read back with rosbags and with the mcap
package (mcap-ros2-support decoding) and compared message by message with what the probe received.
A recorder killed with SIGKILL leaves a bag that ``feeder analyze`` reads and reports as cut short.
"""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from bag.test_analysis import (
    corrupt_middle_chunk,
    listed_counts,
    messages_per_chunk,
    write_feeder_bag,
)
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from ros_test_tools import probe_node, running, wait_until
from rosbags.rosbag2 import Reader as RosbagsReader
from simulator_process import drive, simulator
from stuck_code import TEARDOWN_TIMEOUT_TEXT, stuck_teardown_script

from feeder_ros.bag import Bag, BagWarning, bag_info
from feeder_ros.cli.main import main
from feeder_ros.msg import CarrierState, PartStateArray

BIN = Path(sys.executable).parent
FEEDER = str(BIN / "feeder")
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
STATE_PERIOD_NS = 4_000_000  # state_rate_hz = 250


def stamp_ns(message: Any) -> int:
    stamp = message.header.stamp  # rclpy or mcap-ros2-support message
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def newest_stamps(bag: Path, types: dict[str, Any]) -> dict[str, int]:
    """The newest header stamp [ns] of each topic in ``types`` (topic -> message class) that
    rosbags reads in ``bag``."""
    newest: dict[str, int] = {}
    with RosbagsReader(bag) as reader:
        conns = [c for c in reader.connections if c.topic in types]
        for conn, _, raw in reader.messages(connections=conns):
            stamp = stamp_ns(deserialize_message(raw, types[conn.topic]))
            newest[conn.topic] = max(newest.get(conn.topic, stamp), stamp)
    return newest


def test_record_a_simulator_and_read_the_bag_back(tmp_path: Path) -> None:
    ns = "/rec_cli"
    bag = tmp_path / "run1"
    with simulator(ns), probe_node() as node:
        states: list[CarrierState] = []
        parts: list[PartStateArray] = []
        node.create_subscription(CarrierState, f"{ns}/carrier/state", states.append, RELIABLE)
        node.create_subscription(PartStateArray, f"{ns}/parts/state", parts.append, RELIABLE)
        node.create_timer(0.05, drive(node, ns, 31.0, 40.0))  # the probe's thread sends
        assert wait_until(lambda: bool(states) and states[-1].drive_amplitude_n == 40.0, 20)
        recorder = [FEEDER, "record", "--namespace", ns, "-o", str(bag), "--chunk-size", "64K"]
        with running(recorder) as process:
            assert wait_until(lambda: (bag / "metadata.yaml").exists(), 20), process.poll()
            time.sleep(6.0)  # discovery (slow on a loaded machine), then seconds of data
        assert process.returncode == 0, process.output()
        output = process.output()
        # the probe has everything the recorder kept once it has each topic's last recorded
        # message (one reliable writer per topic: delivered in order)
        last_recorded = newest_stamps(bag, {f"{ns}/carrier/state": CarrierState,
                                            f"{ns}/parts/state": PartStateArray})  # fmt: skip
        assert wait_until(
            lambda: (
                bool(states and parts)
                and stamp_ns(states[-1]) >= last_recorded[f"{ns}/carrier/state"]
                and stamp_ns(parts[-1]) >= last_recorded[f"{ns}/parts/state"]
            ),
            20,
        )

    assert f"into {bag}" in output
    assert "stopped by signal" in output
    metadata = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    topics = {t["topic_metadata"]["name"]: t for t in metadata["topics_with_message_count"]}
    assert {f"{ns}/carrier/state", f"{ns}/imu", f"{ns}/parts/state"} <= set(topics)
    assert all(name.startswith(ns + "/") or name == "/diagnostics" for name in topics)
    state_meta = topics[f"{ns}/carrier/state"]["topic_metadata"]
    assert state_meta["type"] == "feeder_ros/msg/CarrierState"
    assert state_meta["offered_qos_profiles"][0]["reliability"] == "reliable"
    imu_qos = topics[f"{ns}/imu"]["topic_metadata"]["offered_qos_profiles"][0]
    assert imu_qos["reliability"] == "best_effort"  # the simulator's sensor-data QoS

    # rosbags: every message, in order, deserialised by rclpy
    recorded: dict[int, CarrierState] = {}
    log_times = []
    with RosbagsReader(bag) as reader:
        assert reader.message_count == metadata["message_count"]
        conns = [c for c in reader.connections if c.topic == f"{ns}/carrier/state"]
        for _, log_ns, raw in reader.messages(connections=conns):
            message = deserialize_message(raw, CarrierState)
            recorded[stamp_ns(message)] = message
            log_times.append(log_ns)
    stamps = np.array(sorted(recorded))
    assert len(stamps) == topics[f"{ns}/carrier/state"]["message_count"] > 250  # > 1 s
    assert np.all(np.diff(stamps) == STATE_PERIOD_NS), "reliable topic: none lost, none twice"
    start = metadata["starting_time"]["nanoseconds_since_epoch"]
    assert start <= min(log_times)
    assert max(log_times) <= start + metadata["duration"]["nanoseconds"]

    # what the probe received over the same stretch is exactly what was recorded
    probe = {stamp_ns(m): m for m in states if stamps[0] <= stamp_ns(m) <= stamps[-1]}
    assert sorted(probe) == list(stamps)
    for t in stamps[:: max(1, len(stamps) // 200)]:
        for name in ("displacement_m", "velocity_mps", "drive_frequency_hz", "drive_amplitude_n"):
            assert getattr(recorded[t], name) == getattr(probe[t], name)
    assert {recorded[t].drive_amplitude_n for t in stamps} == {40.0}

    # the mcap package with mcap-ros2-support decodes the same messages from our schemas
    decoded = []
    for path in sorted(bag.glob("*.mcap")):
        with path.open("rb") as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            for _, channel, message, ros in reader.iter_decoded_messages(
                topics=[f"{ns}/carrier/state", f"{ns}/parts/state"]
            ):
                if channel.topic.endswith("carrier/state"):
                    decoded.append((stamp_ns(ros), ros.velocity_mps, message.log_time))
    assert [d[0] for d in decoded] == list(stamps)
    assert [d[1] for d in decoded] == [recorded[t].velocity_mps for t in stamps]
    assert [d[2] for d in decoded] == log_times
    received_parts = {stamp_ns(m) for m in parts}
    info = bag_info(bag)
    assert info.topics[f"{ns}/parts/state"].message_count > 50
    assert not info.cut_short
    assert info.problems == []

    # feeder analyze: one driven segment at 31 Hz / 40 N with the ground-truth speed of the
    # messages in the bag
    out = tmp_path / "report"
    result = subprocess.run(
        [FEEDER, "analyze", str(bag), "--output", str(out)], capture_output=True, text=True
    )
    assert result.returncode == 0, result.stderr
    document = json.loads((out / "analysis.json").read_text())
    [analysis] = document["bags"]
    driven = [s for s in analysis["segments"] if s["amplitude_n"] == 40.0]
    assert [s["frequency_hz"] for s in driven] == [31.0]
    # the truth: the parts' displacement over their time on the track, step by step between
    # consecutive samples of a part within the segment
    lo = analysis["start_ns"] + round(driven[0]["start_s"] * 1e9)
    hi = analysis["start_ns"] + round(driven[0]["end_s"] * 1e9)
    last: dict[int, tuple[int, float]] = {}
    moved = took = 0.0
    with RosbagsReader(bag) as reader:
        conns = [c for c in reader.connections if c.topic == f"{ns}/parts/state"]
        for _, _, raw in reader.messages(connections=conns):
            message = deserialize_message(raw, PartStateArray)
            t = stamp_ns(message)
            assert t in received_parts
            for p in message.parts:
                before = last.pop(p.part_id, None)
                if not p.on_track:
                    continue
                last[p.part_id] = (t, p.position_m)
                if before is not None and lo <= before[0] and t <= hi:
                    moved += p.position_m - before[1]
                    took += (t - before[0]) * 1e-9
    assert took > 1.0
    assert np.isclose(driven[0]["speed_ground_truth_mps"], moved / took, rtol=1e-6)
    assert (out / "report.html").read_text().count("data:image/png;base64,") >= 1


def test_duration_topic_list_and_sigterm(tmp_path: Path) -> None:
    ns = "/rec_cli_term"
    with simulator(ns):
        with probe_node() as node:  # the simulator publishes before the recorder's clock starts
            seen: list[CarrierState] = []
            node.create_subscription(CarrierState, f"{ns}/carrier/state", seen.append, RELIABLE)
            assert wait_until(lambda: len(seen) > 10, 30)
        short = subprocess.run(
            [FEEDER, "record", "carrier/state", "--namespace", ns, "--duration", "6",
             "--max-bag-duration", "0.5", "--compression", "lz4", "-o", str(tmp_path / "short")],
            capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        assert short.returncode == 0, short.stderr
        assert "stopped by --duration 6 s" in short.stdout
        info = bag_info(tmp_path / "short")
        assert list(info.topics) == [f"{ns}/carrier/state"]
        assert info.message_count > 100
        assert len(info.files) >= 3  # split every 0.5 s of log time
        listed = yaml.safe_load((tmp_path / "short" / "metadata.yaml").read_text())
        assert len(listed["rosbag2_bagfile_information"]["relative_file_paths"]) == len(info.files)
        with RosbagsReader(tmp_path / "short") as reader:
            assert sum(1 for _ in reader.messages()) == info.message_count
            assert reader.message_count == info.message_count

        process = subprocess.Popen(
            # small chunks: the file grows within a second or two of recording, not after the
            # ~10 s a default 1 MB chunk of these streams takes (on a loaded machine, more)
            [FEEDER, "record", "--namespace", ns, "-o", str(tmp_path / "term"),
             "--chunk-size", "32K"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        try:
            mcap = tmp_path / "term" / "term_0.mcap"  # recording (discovery may take seconds)
            assert wait_until(lambda: mcap.exists() and mcap.stat().st_size > 100_000, 30)
            time.sleep(0.5)
        finally:
            process.send_signal(signal.SIGTERM)
            stdout, _ = process.communicate(timeout=20)
        assert process.returncode == 0
        assert "stopped by signal" in stdout
    bag = Bag(tmp_path / "term")
    info = bag_info(bag)
    assert not info.cut_short
    assert info.problems == []
    assert info.topics[f"{ns}/carrier/state"].message_count > 100
    meta = yaml.safe_load((tmp_path / "term" / "metadata.yaml").read_text())
    assert meta["rosbag2_bagfile_information"]["message_count"] == info.message_count


def test_sigkilled_recorder_leaves_a_bag_reported_cut_short(tmp_path: Path) -> None:
    ns = "/rec_cli_kill"
    bag = tmp_path / "killed"
    with simulator(ns), probe_node() as node:
        node.create_timer(0.05, drive(node, ns, 29.6, 20.0))
        command = [FEEDER, "record", "--namespace", ns, "-o", str(bag), "--chunk-size", "4K"]
        process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            mcap = bag / "killed_0.mcap"
            assert wait_until(lambda: mcap.exists() and mcap.stat().st_size > 100_000, 30)
            time.sleep(1.0)
        finally:
            process.send_signal(signal.SIGKILL)
            process.wait(timeout=10)
        assert process.returncode == -signal.SIGKILL
    result = subprocess.run([FEEDER, "analyze", str(bag)], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "CUT SHORT" in result.stdout
    assert "[cut_short]" in result.stdout
    with pytest.warns(BagWarning, match="cut_short"):
        info = bag_info(Bag(bag))
    assert info.cut_short
    assert info.topics[f"{ns}/carrier/state"].message_count > 100


def test_analyze_cli_outputs_and_bad_input(tmp_path: Path) -> None:
    write_feeder_bag(tmp_path / "good")
    (tmp_path / "junk.mcap").write_bytes(b"not a bag")
    empty = tmp_path / "emptydir"
    empty.mkdir()

    bad = subprocess.run(
        [FEEDER, "analyze", str(tmp_path / "junk.mcap"), str(empty)], capture_output=True, text=True
    )
    assert bad.returncode == 2
    lines = bad.stderr.strip().splitlines()
    assert len(lines) == 2
    assert "junk.mcap" in lines[0]
    assert "not an MCAP bag" in lines[0]
    assert "no metadata.yaml and no .mcap file" in lines[1]

    mixed = subprocess.run(
        [FEEDER, "analyze", str(tmp_path / "good"), str(tmp_path / "junk.mcap"), "--progress",
         "--output", str(tmp_path / "out")],
        capture_output=True, text=True,
    )  # fmt: skip
    assert mixed.returncode == 1, mixed.stderr  # one bag failed: the good one is reported
    assert "comparison:" in mixed.stdout
    assert "100%" in mixed.stderr  # the progress bar
    assert "not an MCAP bag" in mixed.stderr
    rows = (tmp_path / "out" / "comparison.csv").read_text().splitlines()
    assert rows[0].split(",")[:3] == ["bag", "namespace", "status"]
    assert rows[1].split(",")[:3] == [str(tmp_path / "good"), "/cell_a", "ok"]
    assert rows[2].split(",")[2] == "error"
    assert (tmp_path / "out" / "good_segments.csv").is_file()

    # the same bag under another name into the same directory: the tables named after the
    # first bag are the earlier run's, and go (a script reading *_segments.csv would count both)
    first = sorted(p.name for p in (tmp_path / "out").glob("good_*"))
    assert "good_segments.png" in first
    shutil.copytree(tmp_path / "good", tmp_path / "other")
    again = analyze_into(tmp_path / "other", tmp_path / "out")
    assert again.returncode == 0, again.stderr
    assert again.stdout.rstrip().splitlines()[-1] == (
        f"removed {len(first)} file(s) an earlier run wrote to {tmp_path / 'out'} and this one "
        f"did not: {', '.join(first)}"
    )
    assert not list((tmp_path / "out").glob("good_*"))
    assert sorted(p.name for p in (tmp_path / "out").glob("other_*")) == [
        name.replace("good_", "other_", 1) for name in first
    ]


def analyze_into(bag: Path, out: Path) -> subprocess.CompletedProcess[str]:
    """``feeder analyze BAG --output OUT`` in a subprocess."""
    return subprocess.run(
        [FEEDER, "analyze", str(bag), "--output", str(out)], capture_output=True, text=True
    )


def test_analyze_cli_reports_data_lost_to_a_corrupt_chunk(tmp_path: Path) -> None:
    """A corrupt chunk in the middle: the rest is analysed and written, but the loss is said (the
    counts and feed rates are short) and the exit status is 1."""
    write_feeder_bag(tmp_path / "bag", chunk_size=8192, extras=False)
    total, _ = listed_counts(tmp_path / "bag")
    per_chunk = messages_per_chunk(tmp_path / "bag" / "bag_0.mcap")
    middle = corrupt_middle_chunk(tmp_path / "bag" / "bag_0.mcap")
    lost = per_chunk[len(per_chunk) // 2]  # the messages of the corrupted (middle) chunk
    out = tmp_path / "out"
    result = analyze_into(tmp_path / "bag", out)
    assert result.returncode == 1, result.stderr
    lost_s = (middle.message_end_time - middle.message_start_time) * 1e-9
    assert (
        f"DATA LOST: {lost} of {total} recorded messages lost, 1 corrupt chunk(s) skipped, "
        f"about {lost_s:.3g} s"
    ) in result.stdout
    assert "1 corrupt chunk(s) skipped" in result.stderr
    document = json.loads((out / "analysis.json").read_text())
    (bag,) = document["bags"]
    assert bag["lost_messages"] == lost
    assert bag["chunks_lost"] == 1
    assert bag["lost_s"] == pytest.approx(lost_s)
    assert "data lost" in (out / "comparison.csv").read_text()
    assert "DATA LOST: " in (out / "report.html").read_text()  # the terminal's words


def test_bench_bag_quick_run_writes_its_report(tmp_path: Path) -> None:
    """The benchmark still runs (``--quick``, small bags); its timings are not checked here."""
    report = tmp_path / "bench.md"
    completed = subprocess.run(
        [sys.executable, str(Path(__file__).resolve().parents[1] / "bench" / "bench_bag.py"),
         "--quick", "--output", str(report), "--cache", str(tmp_path / "cache")],
        capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    assert completed.returncode == 0, completed.stderr[-2000:]
    text = report.read_text(encoding="utf-8")
    for row in (
        "| feeder_ros.bag read_tables (all fields) | 40,000 |",
        "| mcap + mcap-ros2-support 0.6.0 | 10,000 |",
        "| mcap + mcap-ros2-support-fast 0.8.0 | 10,000 |",
        "| rosbags Reader + deserialize_cdr | 10,000 |",
    ):
        assert row in text
    assert "| 6 | yes |" in text  # the sweep's six segments, estimator speeds as written


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["bad_topic!"], "topic 'bad_topic!': Invalid topic name"),
        (["--namespace", "bad ns"], "namespace 'bad ns': Invalid namespace"),
        (["--duration", "0"], "argument --duration: '0' must be positive"),
    ],
)
def test_record_refuses_names_that_are_not_ros_names_and_a_zero_duration(
    tmp_path: Path, args: list[str], needle: str
) -> None:
    bag = tmp_path / "bag"
    result = subprocess.run(
        [FEEDER, "record", "-o", str(bag), "--duration", "2", *args],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2, result.stdout + result.stderr
    assert needle in result.stderr
    assert not bag.exists()  # refused before the recorder started


def test_record_refuses_an_existing_bag(tmp_path: Path) -> None:
    existing = tmp_path / "bag"
    existing.mkdir()
    (existing / "keep.txt").write_text("mine")
    result = subprocess.run(
        [FEEDER, "record", "-o", str(existing), "--duration", "1"], capture_output=True, text=True
    )
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        f"feeder record: error: bag writer {existing}: the bag path exists and is not an empty "
        "directory"
    ]
    assert sorted(p.name for p in existing.iterdir()) == ["keep.txt"]


RECORDER_WITH_A_STUCK_TEARDOWN = stuck_teardown_script(
    """
from pathlib import Path

from feeder_ros import recording

recording.TopicRecorder.destroy_node = stuck
options = recording.RecordingOptions(
    output=Path(sys.argv[1]), namespace=sys.argv[2], duration_s=float(sys.argv[3])
)
recording.record(options)
"""
)


def test_a_recorder_whose_teardown_hangs_ends_with_its_bag_complete(tmp_path: Path) -> None:
    ns = "/rec_stuck_teardown"
    script = tmp_path / "stuck_recorder.py"
    script.write_text(RECORDER_WITH_A_STUCK_TEARDOWN)
    bag = tmp_path / "stuck"
    with simulator(ns):
        result = subprocess.run(
            [sys.executable, str(script), str(bag), ns, "6"],
            capture_output=True, text=True, timeout=120,  # without the watchdog: never ends
        )  # fmt: skip
    assert result.returncode == 1, result.stderr
    assert TEARDOWN_TIMEOUT_TEXT in result.stderr
    assert "in stuck" in result.stderr  # the stuck call, named on stderr
    info = bag_info(Bag(bag))  # closed before the teardown: footer, summary, metadata.yaml
    assert not info.cut_short
    assert info.problems == []
    assert info.topics[f"{ns}/carrier/state"].message_count > 100
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())
    assert meta["rosbag2_bagfile_information"]["message_count"] == info.message_count
    with RosbagsReader(bag) as reader:
        assert reader.message_count == info.message_count


@pytest.mark.parametrize(
    ("option", "value", "needle"),
    [
        ("--chunk-size", "1e300G", "'1e300G' is too large (at most 1024G)"),
        ("--max-bag-size", "2048G", "'2048G' is too large (at most 1024G)"),
        ("--chunk-size", "0.5", "'0.5' is less than one byte"),
        ("--chunk-size", "nan", "'nan' must be >= 0"),
    ],
)
def test_record_sizes_are_checked_by_the_parser(
    tmp_path: Path, option: str, value: str, needle: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["record", "-o", str(tmp_path / "bag"), option, value, "--duration", "1"])
    assert exit_info.value.code == 2
    assert needle in capsys.readouterr().err
    assert not (tmp_path / "bag").exists()


def test_analyze_cli_reports_a_missing_split_file_as_data_lost(tmp_path: Path) -> None:
    """Not only corrupt chunks: a split file listed in metadata.yaml but gone is lost data too
    (exit status 1, the loss named on stdout, stderr and in the JSON)."""
    write_feeder_bag(tmp_path / "bag", chunk_size=8192, extras=False, split_s=1)
    total, per_file = listed_counts(tmp_path / "bag")
    (tmp_path / "bag" / "bag_2.mcap").unlink()
    out = tmp_path / "out"
    result = analyze_into(tmp_path / "bag", out)
    assert result.returncode == 1, result.stderr
    lost = f"{per_file['bag_2.mcap']} of {total} recorded messages lost"
    assert f"DATA LOST: {lost}, 1 missing file(s), about 0.999 s of recording" in result.stdout
    assert f"{tmp_path / 'bag'}: data lost ({lost}, 1 missing file(s)" in result.stderr
    (bag,) = json.loads((out / "analysis.json").read_text())["bags"]
    missing, count = bag["data_losses"]
    assert missing.startswith(f"[missing_file] {tmp_path / 'bag' / 'bag_2.mcap'}")
    assert count.startswith(f"[lost_messages] {lost}")
    assert bag["lost_messages"] == per_file["bag_2.mcap"]
    assert bag["chunks_lost"] == 0
    assert bag["lost_s"] == pytest.approx(0.999)
    assert "data lost" in (out / "comparison.csv").read_text()
