"""``feeder_ros.bag.analysis`` on bags written from code with known contents (real ROS messages
serialized by rclpy): every segment value is computed by hand from what was written."""

from __future__ import annotations

import json
import math
import re
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from mcap.reader import make_reader
from mcap.records import Message, MessageIndex
from mcap.stream_reader import StreamReader
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Imu
from std_msgs.msg import String

from feeder_ros.bag import BagWriter, accumulator, analysis
from feeder_ros.bag.analysis import AnalysisError, analyze_bag, analyze_bags
from feeder_ros.bag.report import format_summary, write_outputs
from feeder_ros.msg import (
    CarrierState,
    CarrierStateBatch,
    DriveCommand,
    PartExit,
    PartSensorEvent,
    PartState,
    PartStateArray,
    VehicleEstimate,
)

T0 = 1_750_000_000_000_000_000
MS = 1_000_000
S = 1_000_000_000

# (start s, end s, frequency Hz, amplitude N): the drive plan of the standard test bag
PLAN = [(0.0, 2.0, 30.0, 20.0), (2.0, 4.0, 40.0, 20.0), (4.0, 5.0, 40.0, 0.0)]
# per segment: estimator speed, truth speeds of the two parts, truth phases, exits
EST_SPEED = [0.001, 0.003, 0.0]
EST_SLIP = [0.25, 0.5, 0.0]
TRUTH = [((0.002, 0.004), (0, 1)), ((0.006, 0.010), (1, 2)), ((0.0, 0.0), (0, 0))]
EXITS = [3, 6, 0]


def stamp(message: Any, t_ns: int) -> Any:
    if not hasattr(message, "header"):
        return message
    message.header.stamp.sec = t_ns // S
    message.header.stamp.nanosec = t_ns % S
    return message


def cdr(message: Any) -> bytes:
    return bytes(serialize_message(message))


def segment_at(t_s: float) -> int:
    return next(i for i, (lo, hi, _, _) in enumerate(PLAN) if lo <= t_s < hi)


def write_feeder_bag(
    path: Path,
    ns: str = "/cell_a",
    chunk_size: int = 1 << 20,
    batches: bool = False,
    carrier: bool = True,
    extras: bool = True,
    split_s: int = 0,
    killed: Path | None = None,
) -> None:
    """5 s of a feeder: carrier state (1 kHz), estimate and part states (100 Hz), sensor events,
    exits, drive commands, diagnostics, plus unrelated topics; all stamped on exact grids.
    ``split_s``: a new file every so many seconds of recording (0: one file). ``killed``: also
    copy the bag there just before it is closed (every chunk written, the last file without its
    summary, metadata.yaml as of the last split): what a recorder killed at that moment leaves."""
    with BagWriter(path, chunk_size=chunk_size, max_file_duration_ns=split_s * S) as w:
        topics = {
            "state": (f"{ns}/carrier/state", "feeder_ros/msg/CarrierState"),
            "batch": (f"{ns}/carrier/state_batch", "feeder_ros/msg/CarrierStateBatch"),
            "est": (f"{ns}/estimate", "feeder_ros/msg/VehicleEstimate"),
            "parts": (f"{ns}/parts/state", "feeder_ros/msg/PartStateArray"),
            "events": (f"{ns}/parts/sensor_events", "feeder_ros/msg/PartSensorEvent"),
            "exit": (f"{ns}/parts/exit", "feeder_ros/msg/PartExit"),
            "cmd": (f"{ns}/drive/command", "feeder_ros/msg/DriveCommand"),
            "diag": ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
            "imu": (f"{ns}/imu", "sensor_msgs/msg/Imu"),
            "chatter": ("/chatter", "std_msgs/msg/String"),
        }
        for name, type_name in topics.values():
            w.add_topic(name, type_name)

        def put(key: str, message: Any, t_ns: int) -> None:
            w.write(topics[key][0], cdr(stamp(message, t_ns)), t_ns + 50_000)

        exits_done = [0, 0, 0]
        total_exits = 0
        positions = [0.0, 0.0]  # the truth's parts, moved at their segment's speeds
        for k in range(5000):  # 1 ms steps
            t_ns = T0 + k * MS
            t_s = k * 1e-3
            seg = segment_at(t_s)
            _, _, freq, amp = PLAN[seg]
            if k in (0, 2000, 4000):
                put("cmd", DriveCommand(enabled=amp > 0, frequency_hz=freq, amplitude_n=amp), t_ns)
            if carrier and not batches:
                put(
                    "state",
                    CarrierState(drive_frequency_hz=freq, drive_amplitude_n=amp, velocity_mps=0.1),
                    t_ns,
                )
            if carrier and batches and k % 10 == 0:
                message = CarrierStateBatch(sample_period_s=1e-3)
                message.drive_frequency_hz = [
                    PLAN[segment_at((k + j) * 1e-3)][2] for j in range(10)
                ]
                message.drive_amplitude_n = [PLAN[segment_at((k + j) * 1e-3)][3] for j in range(10)]
                put("batch", message, t_ns)
            if extras:
                put("imu", Imu(), t_ns)
            if k % 10 == 0:
                # the estimator: status OK except the first 100 ms of each segment (SETTLING,
                # garbage values that the analysis must ignore)
                settling = (k % 2000) < 100 and k < 4000
                estimate = VehicleEstimate(
                    mean_speed_mps=99.0 if settling else EST_SPEED[seg],
                    slip_fraction=0.9 if settling else EST_SLIP[seg],
                    status=VehicleEstimate.STATUS_SETTLING if settling else 0,
                )
                put("est", estimate, t_ns)
                speeds, phases = TRUTH[seg]
                parts = PartStateArray()
                for i in range(2):
                    if k:
                        positions[i] += speeds[i] * 0.01  # over the 10 ms up to this sample
                    parts.parts.append(
                        PartState(
                            part_id=i + 1,
                            position_m=positions[i],
                            velocity_mps=speeds[i],
                            phase=phases[i],
                            on_track=True,
                        )
                    )
                parts.parts.append(PartState(part_id=9, velocity_mps=5.0, phase=1, on_track=False))
                put("parts", parts, t_ns)
            if k % 100 == 50 and exits_done[seg] < EXITS[seg]:
                exits_done[seg] += 1
                total_exits += 1
                put("exit", PartExit(part_id=total_exits, parts_out_total=total_exits), t_ns)
            if extras and k % 1000 == 0:
                put("chatter", String(data="hello"), t_ns)
        # sensor transits: part 5 passes sensor 0 (0.10 m) at 0.5 s and sensor 1 (0.25 m) at
        # 0.8 s (0.5 m/s, segment 0); part 6 from 2.5 s to 3.0 s (0.3 m/s, segment 1)
        for part, t0, t1 in ((5, 500, 800), (6, 2500, 3000)):
            for sensor, pos, t_ms in ((0, 0.10, t0), (1, 0.25, t1)):
                for present, dt in ((True, 0), (False, 20)):
                    event = PartSensorEvent(
                        sensor_index=sensor, sensor_position_m=pos, part_id=part, present=present
                    )
                    put("events", event, T0 + (t_ms + dt) * MS)
        # diagnostics at 1 Hz: "drive" OK, WARN at 2 s, OK again at 4 s; "sensor" always OK
        for second in range(5):
            level = DiagnosticStatus.WARN if 2 <= second < 4 else DiagnosticStatus.OK
            array = DiagnosticArray()
            array.status = [
                DiagnosticStatus(level=level, name="feeder: drive", message=f"s{second}"),
                DiagnosticStatus(level=DiagnosticStatus.OK, name="feeder: sensor", message="ok"),
            ]
            put("diag", array, T0 + second * S + 1)
        if killed is not None:
            w.flush()
            shutil.copytree(path, killed)


def check_standard(result: Any, drive_source: str = "carrier state", end_s: float = 4.999) -> None:
    assert result.ok
    assert result.drive_source == drive_source
    assert len(result.segments) == 3
    for seg, (lo, hi, freq, amp) in zip(result.segments, PLAN, strict=True):
        i = seg.index
        assert seg.start_s == pytest.approx(lo, abs=1e-9)
        # the last segment ends at the last message (sensor/diag events are earlier)
        assert seg.end_s == pytest.approx(hi if i < 2 else end_s, abs=1e-9)
        assert (seg.frequency_hz, seg.amplitude_n) == ((freq, amp) if amp else (0.0, 0.0))
        assert seg.speed_estimate_mps == pytest.approx(EST_SPEED[i], rel=1e-12)
        assert seg.slip_estimate == pytest.approx(EST_SLIP[i], rel=1e-12)
        speeds, phases = TRUTH[i]
        assert seg.speed_ground_truth_mps == pytest.approx(np.mean(speeds), rel=1e-12)
        if amp:  # 100 Hz part states of a 30 or 40 Hz drive: 10 or 5 phases, no share given
            assert math.isnan(seg.slip_ground_truth)
        else:
            assert seg.slip_ground_truth == pytest.approx(np.mean([p != 0 for p in phases]))
        assert seg.parts_exited == EXITS[i]
        assert seg.feed_rate_per_min == pytest.approx(EXITS[i] / (seg.duration_s / 60.0))
    assert result.segments[0].speed_sensors_mps == pytest.approx(0.5, rel=1e-9)
    assert result.segments[1].speed_sensors_mps == pytest.approx(0.3, rel=1e-9)
    assert math.isnan(result.segments[2].speed_sensors_mps)
    assert [s.transits for s in result.segments] == [1, 1, 0]
    # best speed: ground truth first
    assert result.segments[1].speed_mps == pytest.approx(0.008)
    # sweep: two frequencies at 20 N (the "off" segment is not an operating point)
    points = [(p.amplitude_n, p.frequency_hz) for p in result.frequency_response]
    assert points == [(20.0, 30.0), (20.0, 40.0)]
    assert result.frequency_response[1].speed_mps == pytest.approx(0.008)
    changes = [(round(d.t_s, 6), d.name, d.level_name) for d in result.diagnostics]
    assert changes == [
        (0.0, "feeder: drive", "OK"),
        (0.0, "feeder: sensor", "OK"),
        (2.0, "feeder: drive", "WARN"),
        (4.0, "feeder: drive", "OK"),
    ]


def test_segments_speeds_slip_feed_rate_and_diagnostics(tmp_path: Path) -> None:
    write_feeder_bag(tmp_path / "bag")
    result = analyze_bag(tmp_path / "bag")
    check_standard(result)
    assert result.messages["feeder_ros/msg/CarrierState"] == 5000
    assert result.topics["feeder_ros/msg/VehicleEstimate"] == ["/cell_a/estimate"]
    assert "sensor_msgs/msg/Imu" not in result.messages  # unrelated topics are not decoded
    [problem] = result.problems
    assert problem.startswith("[aliased] no ground-truth slip fraction in 2 segment(s) (the first ")
    assert "sampled 10 of 36 phase bins of the 30 Hz drive cycle" in problem
    assert not result.cut_short


@pytest.mark.parametrize("chunk_size", [2048, 64 << 10])
def test_results_do_not_depend_on_chunking(
    tmp_path: Path, chunk_size: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Streaming: samples are reduced between chunks (here at every chunk boundary), once the
    drive timeline has passed them; the pending buffer stays small."""
    write_feeder_bag(tmp_path / "bag", chunk_size=chunk_size, ns="/remapped/feeder_7")
    monkeypatch.setattr(analysis, "_FLUSH_BATCH", 0)
    peak = [0]
    flush = accumulator.Accumulator.flush

    def watched(self: Any, final: bool = False) -> None:
        peak[0] = max(peak[0], self.pending_count)
        flush(self, final)

    monkeypatch.setattr(accumulator.Accumulator, "flush", watched)
    check_standard(analyze_bag(tmp_path / "bag"))
    if chunk_size == 2048:
        assert 0 < peak[0] < 200  # of 3012 metric samples


def test_single_mcap_file_and_state_batches(tmp_path: Path) -> None:
    write_feeder_bag(tmp_path / "bag", batches=True)
    result = analyze_bag(tmp_path / "bag" / "bag_0.mcap")
    check_standard(result)
    assert result.messages["feeder_ros/msg/CarrierStateBatch"] == 500


def test_drive_commands_alone_give_the_segments(tmp_path: Path) -> None:
    write_feeder_bag(tmp_path / "bag", carrier=False)
    result = analyze_bag(tmp_path / "bag")
    check_standard(result, drive_source="drive command", end_s=4.99)  # last: 100 Hz topics


def test_short_segments_are_transient(tmp_path: Path) -> None:
    write_feeder_bag(tmp_path / "bag")
    result = analyze_bag(tmp_path / "bag", min_segment_s=1.5)
    assert [s.frequency_hz for s in result.segments] == [30.0, 40.0]
    assert result.transient_segments == 1


def test_no_sweep_without_two_frequencies(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    with BagWriter(path) as w:
        w.add_topic("/f/carrier/state", "feeder_ros/msg/CarrierState")
        for k in range(3000):
            amp = 10.0 if k < 1500 else 30.0
            message = CarrierState(drive_frequency_hz=25.0, drive_amplitude_n=amp)
            w.write("/f/carrier/state", cdr(stamp(message, T0 + k * MS)), T0 + k * MS)
    result = analyze_bag(path)
    assert [(s.frequency_hz, s.amplitude_n) for s in result.segments] == [
        (25.0, 10.0),
        (25.0, 30.0),
    ]
    assert result.frequency_response == []
    assert math.isnan(result.segments[0].speed_mps)


def test_log_time_is_used_where_the_stamp_is_zero(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    with BagWriter(path) as w:
        w.add_topic("/exit", "feeder_ros/msg/PartExit")
        for k in range(4):
            w.write("/exit", cdr(PartExit(part_id=k)), T0 + k * 20 * S)
    result = analyze_bag(path)
    assert result.duration_s == pytest.approx(60.0)
    assert result.drive_source == "none"
    [segment] = result.segments
    assert segment.frequency_hz is None
    assert segment.parts_exited == 4
    assert result.totals()["feed_rate_per_min"] == pytest.approx(4.0)


def test_several_bags_and_outputs(tmp_path: Path) -> None:
    write_feeder_bag(tmp_path / "one")
    write_feeder_bag(tmp_path / "two", batches=True)
    (tmp_path / "junk.mcap").write_bytes(b"not a bag at all")
    results = analyze_bags([tmp_path / "one", tmp_path / "two", tmp_path / "junk.mcap"])
    assert [r.ok for r in results] == [True, True, False]
    assert "not an MCAP bag" in (results[2].error or "")
    text = format_summary(results)
    assert "comparison:" in text
    assert "feeder: drive" in text
    out = tmp_path / "out"
    written = {p.name for p in write_outputs(results, out)}
    assert {
        "one_segments.csv",
        "one_frequency_response.csv",
        "one_diagnostics.csv",
        "one_segments.png",
        "one_frequency_response.png",
        "two_segments.csv",
        "comparison.csv",
        "analysis.json",
        "report.html",
    } <= written
    rows = (out / "one_segments.csv").read_text().splitlines()
    assert rows[0].startswith("segment,start_s,end_s,frequency_hz,amplitude_n,speed_mm_s")
    assert len(rows) == 4
    assert rows[2].split(",")[3:5] == ["40.0", "20.0"]
    assert float(rows[2].split(",")[5]) == pytest.approx(8.0)
    document = json.loads((out / "analysis.json").read_text())
    assert [b["error"] is None for b in document["bags"]] == [True, True, False]
    assert document["bags"][0]["segments"][0]["speed_estimate_mps"] == pytest.approx(0.001)
    assert document["bags"][0]["segments"][2]["speed_sensors_mps"] is None  # NaN -> null
    page = (out / "report.html").read_text()
    assert page.count("data:image/png;base64,") == 4
    assert "src='http" not in page
    assert 'src="http' not in page
    assert (out / "one_segments.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# ------------------------------------------------------------------------------- bad input


def test_not_a_bag(tmp_path: Path) -> None:
    (tmp_path / "x.mcap").write_bytes(b"\x00" * 100)
    with pytest.raises(AnalysisError, match="not an MCAP bag"):
        analyze_bag(tmp_path / "x.mcap")
    with pytest.raises(FileNotFoundError, match="no bag at"):
        analyze_bag(tmp_path / "missing")


def test_empty_bag(tmp_path: Path) -> None:
    with BagWriter(tmp_path / "bag") as w:
        w.add_topic("/f/carrier/state", "feeder_ros/msg/CarrierState")
    with pytest.raises(AnalysisError, match="empty bag"):
        analyze_bag(tmp_path / "bag")


def test_no_feeder_topics(tmp_path: Path) -> None:
    with BagWriter(tmp_path / "bag") as w:
        w.add_topic("/chatter", "std_msgs/msg/String")
        w.write("/chatter", cdr(String(data="x")), T0)
    with pytest.raises(
        AnalysisError, match=r"no feeder topics \(found /chatter \(std_msgs/msg/String\)\)"
    ):
        analyze_bag(tmp_path / "bag")


def listed_counts(bag: Path) -> tuple[int, dict[str, int]]:
    """What metadata.yaml (written by the writer when it closed the bag) counts: the total and
    the messages per file."""
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    return meta["message_count"], {f["path"]: f["message_count"] for f in meta["files"]}


def stream_count(mcap: Path) -> int:
    """Messages the mcap package's stream reader reads from a file, up to where it fails (the
    chunks before a cut): an independent count of the readable messages."""
    count = 0
    with mcap.open("rb") as stream:
        try:
            for record in StreamReader(stream).records:
                count += isinstance(record, Message)
        except Exception:  # the file's end cut a record: what came before it counts
            pass
    return count


def messages_per_chunk(mcap: Path) -> list[int]:
    """Messages in each chunk of a whole file, in file order (the mcap package's stream reader:
    each chunk's messages are followed by its message indexes)."""
    counts: list[int] = []
    current = 0
    with mcap.open("rb") as stream:
        for record in StreamReader(stream).records:
            if isinstance(record, Message):
                current += 1
            elif isinstance(record, MessageIndex) and current:
                counts.append(current)
                current = 0
    return counts


def test_truncated_file_gives_partial_results_and_counts_the_loss(tmp_path: Path) -> None:
    """A copy of a closed bag cut in half: what was read is analysed, and the messages past the
    cut are counted lost (metadata.yaml, written when the bag was closed, counts them)."""
    write_feeder_bag(tmp_path / "bag", chunk_size=8192, extras=False)
    recorded, _ = listed_counts(tmp_path / "bag")
    mcap = tmp_path / "bag" / "bag_0.mcap"
    data = mcap.read_bytes()
    mcap.write_bytes(data[: len(data) // 2])
    readable = stream_count(mcap)
    assert 0 < readable < recorded
    result = analyze_bag(tmp_path / "bag")
    assert result.cut_short
    assert result.data_lost
    assert result.loss is not None
    assert (result.loss.recorded, result.loss.readable) == (recorded, readable)
    assert result.loss.lost == recorded - readable
    assert result.loss.exact
    assert result.loss_summary().startswith(
        f"{recorded - readable} of {recorded} recorded messages lost"
    )
    assert result.as_dict()["lost_messages"] == recorded - readable
    assert any("[cut_short]" in p for p in result.problems)
    assert any(p.startswith("[lost_messages]") for p in result.problems)
    assert 0 < result.duration_s < 5.0
    assert result.segments[0].frequency_hz == 30.0
    assert result.segments[0].speed_estimate_mps == pytest.approx(0.001)


def corrupt_middle_chunk(mcap: Path) -> Any:
    """Zero 64 bytes inside the compressed records of the file's middle chunk; its index entry
    (offsets, log times) is returned."""
    with mcap.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    middle = chunks[len(chunks) // 2]
    data = bytearray(mcap.read_bytes())
    at = middle.chunk_start_offset + middle.chunk_length // 2
    data[at : at + 64] = bytes(64)
    mcap.write_bytes(bytes(data))
    return middle


def test_corrupt_chunk_is_named_and_the_rest_analysed(tmp_path: Path) -> None:
    write_feeder_bag(tmp_path / "bag", chunk_size=8192, extras=False)
    middle = corrupt_middle_chunk(tmp_path / "bag" / "bag_0.mcap")
    result = analyze_bag(tmp_path / "bag")
    corrupt = [p for p in result.problems if p.startswith("[corrupt_chunk]")]
    assert len(corrupt) == 1
    assert f"byte {middle.chunk_start_offset}" in corrupt[0]
    # the loss is counted: the recording time the skipped chunk spanned (its index's log times)
    lost_s = (middle.message_end_time - middle.message_start_time) * 1e-9
    assert lost_s > 0.0
    assert result.data_lost
    assert result.chunks_lost == 1
    assert result.lost_s == pytest.approx(lost_s, abs=1e-12)
    assert f"({lost_s:.4g} s of recording lost)" in corrupt[0]
    assert result.as_dict()["chunks_lost"] == 1
    assert [s.frequency_hz for s in result.segments][:2] == [30.0, 40.0]
    assert result.segments[0].speed_ground_truth_mps == pytest.approx(0.003)


@pytest.mark.parametrize("damage", ["missing", "empty", "cut_short", "record", "malformed"])
def test_lost_split_file_or_records_are_data_lost(tmp_path: Path, damage: str) -> None:
    """Whatever keeps recorded messages from being read counts as lost data, not only a corrupt
    chunk: a missing, empty or cut-short split file before the last, a damaged record header, a
    malformed message. The rest is analysed; counts come out short."""
    path = tmp_path / "bag"
    write_feeder_bag(path, chunk_size=8192, extras=False, split_s=1)
    # five files of the 1 kHz loop, then more: the events and diagnostics written after it
    assert len(list(path.glob("*.mcap"))) >= 5
    second = path / "bag_1.mcap"
    recorded, per_file = listed_counts(path)
    in_second = per_file["bag_1.mcap"]
    in_chunks = messages_per_chunk(second)
    expected = {
        "missing": "1 missing file(s), about 0.999 s of recording",
        "empty": "1 file(s) that are not MCAP",
        "cut_short": "1 split file(s) cut short before the last",
        "record": "1 damaged record(s) skipped over",
        "malformed": "1 chunk(s) with malformed messages dropped",
    }[damage]
    if damage == "missing":
        second.unlink()
    elif damage == "empty":
        second.write_bytes(b"")
    elif damage == "cut_short":  # at the start of its middle chunk (no chunk cut in two)
        with second.open("rb") as stream:
            summary = make_reader(stream).get_summary()
        assert summary is not None
        starts = sorted(c.chunk_start_offset for c in summary.chunk_indexes)
        second.write_bytes(second.read_bytes()[: starts[len(starts) // 2]])
    elif damage == "record":
        with second.open("rb") as stream:
            summary = make_reader(stream).get_summary()
        assert summary is not None
        offset = sorted(c.chunk_start_offset for c in summary.chunk_indexes)[1]
        data = bytearray(second.read_bytes())
        data[offset] = 0x7F  # the record header: the scan resumes at the next chunk
        second.write_bytes(bytes(data))
    else:
        with BagWriter(tmp_path / "extra") as w:  # an exit message cut before its last field
            w.add_topic("/cell_a/parts/exit", "feeder_ros/msg/PartExit")
            w.write("/cell_a/parts/exit", cdr(PartExit(part_id=99))[:-4], T0 + 4500 * MS)
        (tmp_path / "extra" / "extra_0.mcap").rename(path / "bag_99.mcap")
    # the messages lost, counted: a missing or empty file's from metadata.yaml, a cut file's
    # past its cut, a damaged chunk's from the file's summary; a malformed message is readable
    lost = in_second if damage in ("missing", "empty") else 0
    if damage == "cut_short":
        lost = in_second - stream_count(second)
        assert 0 < lost < in_second
    elif damage == "record":
        lost = in_chunks[1]
    if lost:
        expected = f"{lost} of {recorded} recorded messages lost, {expected}"
    result = analyze_bag(path)
    assert result.ok
    assert result.data_lost
    assert result.loss is not None
    assert result.loss.lost == lost
    assert result.loss_summary() == expected
    assert result.as_dict()["data_losses"] == [str(p) for p in result.data_losses]
    assert all(str(p) in result.problems for p in result.data_losses)
    write_feeder_bag(tmp_path / "whole", chunk_size=8192, extras=False, split_s=1)
    whole = analyze_bag(tmp_path / "whole")
    assert not whole.data_lost
    if damage != "malformed":  # messages of the second's file are missing
        assert sum(result.messages.values()) < sum(whole.messages.values())
    assert "DATA LOST: " + expected in format_summary([result])


def test_cut_short_last_file_of_a_killed_recorder_is_no_loss(tmp_path: Path) -> None:
    """A recorder killed between chunks leaves its last file without a summary and metadata.yaml
    as of its last split: every chunk it wrote is read, nothing is counted lost, and the number
    recorded is said to be unknown (metadata.yaml does not count the last file)."""
    path = tmp_path / "killed"
    write_feeder_bag(tmp_path / "bag", chunk_size=8192, extras=False, split_s=1, killed=path)
    last = max(path.glob("*.mcap"), key=lambda p: int(p.stem.split("_")[1]))
    assert not last.read_bytes().endswith(b"\x89MCAP0\r\n")  # no footer
    _, per_file = listed_counts(path)
    assert per_file[last.name] == 0  # metadata.yaml as the writer left it when it opened the file
    result = analyze_bag(path)
    assert result.cut_short
    assert not result.data_lost
    assert result.data_losses == []
    assert result.loss is not None
    assert result.loss.lost == 0
    assert not result.loss.exact
    assert result.loss.unknown == (
        f"{last.name} ends without a summary and metadata.yaml lists 0 message(s) in it, fewer "
        f"than the {stream_count(last)} found (written before the file was finished)",
    )
    assert "messages recorded: unknown" in format_summary([result])
    whole = analyze_bag(tmp_path / "bag")  # the same recording, closed: nothing was lost
    assert whole.loss is not None
    assert (whole.loss.lost, whole.loss.exact) == (0, True)
    assert result.loss.readable == whole.loss.readable


def test_diagnostics_not_in_metadata_yaml_are_found(tmp_path: Path) -> None:
    """A recorder killed before it rewrote metadata.yaml leaves no topics listed there: the
    diagnostics are found in the data all the same."""
    write_feeder_bag(tmp_path / "bag")
    meta = tmp_path / "bag" / "metadata.yaml"
    data = yaml.safe_load(meta.read_text())
    data["rosbag2_bagfile_information"]["topics_with_message_count"] = []
    meta.write_text(yaml.safe_dump(data))
    check_standard(analyze_bag(tmp_path / "bag"))


def test_impossible_values_are_left_out_and_named(tmp_path: Path) -> None:
    """Values the analysis cannot use are left out with a problem naming one of them, not
    silently: impossible batch sample periods, non-finite estimates and drive settings, and drive
    samples stamped before ones already read (one outlying stamp far ahead)."""
    path = tmp_path / "bag"
    with BagWriter(path) as w:
        w.add_topic("/f/carrier/state_batch", "feeder_ros/msg/CarrierStateBatch")
        w.add_topic("/f/carrier/state", "feeder_ros/msg/CarrierState")
        w.add_topic("/f/estimate", "feeder_ros/msg/VehicleEstimate")
        for k, period in enumerate([1e-3, math.nan, 1e6, -1e-3, 1e-3]):
            batch = CarrierStateBatch(sample_period_s=period)
            batch.drive_frequency_hz = [30.0] * 10
            batch.drive_amplitude_n = [20.0] * 9 + [math.inf]
            w.write("/f/carrier/state_batch", cdr(stamp(batch, T0 + k * 10 * MS)), T0 + k * 10 * MS)
        for k, speed in enumerate([0.01, math.nan, 0.01]):
            estimate = VehicleEstimate(mean_speed_mps=speed, slip_fraction=0.5)
            w.write("/f/estimate", cdr(stamp(estimate, T0 + k * MS)), T0 + k * MS)
    result = analyze_bag(path)
    problems = "\n".join(result.problems)
    for line in (
        "[bad_value] 3 CarrierStateBatch message(s) with an impossible sample_period_s left out "
        "(for example nan)",
        # the two batches read each end with an infinite amplitude
        "[bad_value] 2 non-finite drive amplitude(s) taken as off (for example inf)",
        "[bad_value] 1 non-finite VehicleEstimate.mean_speed_mps left out (for example nan)",
    ):
        assert line in problems
    assert "out_of_order" not in problems

    path = tmp_path / "outlier"
    with BagWriter(path, chunk_size=4096) as w:  # chunks of about 100 messages
        w.add_topic("/f/carrier/state", "feeder_ros/msg/CarrierState")
        for k in range(2000):
            t_ns = T0 + k * MS + (100 * S if k == 500 else 0)  # one stamp 100 s ahead
            freq = 30.0 if k < 1000 else 40.0
            state = CarrierState(drive_frequency_hz=freq, drive_amplitude_n=20.0)
            w.write("/f/carrier/state", cdr(stamp(state, t_ns)), T0 + k * MS)
    result = analyze_bag(path)
    (note,) = [p for p in result.problems if p.startswith("[out_of_order]")]
    # every sample of the chunks after the outlier's: the change to 40 Hz at 1 s is lost
    match = re.match(r"\[out_of_order\] (\d+) carrier state sample\(s\) stamped before", note)
    assert match is not None
    assert 1400 <= int(match[1]) < 1500
    assert "(up to t = 100.5 s)" in note


def test_missing_metadata_yaml(tmp_path: Path) -> None:
    write_feeder_bag(tmp_path / "bag")
    (tmp_path / "bag" / "metadata.yaml").unlink()
    result = analyze_bag(tmp_path / "bag")
    check_standard(result)
    assert any("[missing_metadata]" in p for p in result.problems)


def test_unrelated_unknown_types_are_ignored(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    with BagWriter(path) as w:
        w.add_topic("/f/parts/exit", "feeder_ros/msg/PartExit")
        w.add_topic(
            "/other", "acme_msgs/msg/Gadget", schema_text="int32 x\n", type_hash="RIHS01_00"
        )
        for k in range(3):
            w.write("/other", b"\x00\x01\x00\x00\x05\x00\x00\x00", T0 + k * S)
            w.write("/f/parts/exit", cdr(stamp(PartExit(part_id=k), T0 + k * S)), T0 + k * S)
    result = analyze_bag(path)
    assert [s.parts_exited for s in result.segments] == [3]
    assert result.problems == []


OLD_PART_EXIT = (  # an old PartExit without part_id: its fields do not match ours
    "std_msgs/Header header\nuint64 total\n"
    + "=" * 80
    + "\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
    + "=" * 80
    + "\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
)


def test_feeder_type_with_a_foreign_definition_is_left_out(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    with BagWriter(path) as w:
        w.add_topic("/f/parts/exit", "feeder_ros/msg/PartExit", schema_text=OLD_PART_EXIT)
        w.add_topic("/f/carrier/state", "feeder_ros/msg/CarrierState")
        for k in range(2000):
            t_ns = T0 + k * MS
            state = CarrierState(drive_frequency_hz=30.0, drive_amplitude_n=10.0)
            w.write("/f/carrier/state", cdr(stamp(state, t_ns)), t_ns)
            if k % 100 == 0:
                w.write("/f/parts/exit", cdr(stamp(PartExit(part_id=1), t_ns)), t_ns)
    result = analyze_bag(path)
    [segment] = result.segments
    assert (segment.frequency_hz, segment.amplitude_n) == (30.0, 10.0)
    assert segment.parts_exited == 0
    [problem] = result.problems
    assert problem.startswith("[foreign_definition] feeder_ros/msg/PartExit")
    assert "part_id" in problem


def test_only_a_foreign_definition_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "bag"
    with BagWriter(path) as w:
        w.add_topic("/f/parts/exit", "feeder_ros/msg/PartExit", schema_text=OLD_PART_EXIT)
        w.write("/f/parts/exit", cdr(stamp(PartExit(part_id=1), T0)), T0)
    with pytest.raises(AnalysisError, match=r"no usable feeder data; \[foreign_definition\]"):
        analyze_bag(path)


def test_the_truth_is_the_parts_displacement_not_their_sampled_velocity(tmp_path: Path) -> None:
    """Part states at 50 Hz of a part whose velocity swings at 150 Hz (the 5th harmonic of a
    30 Hz drive cycle) about its mean V: every sample lands on the swing's crest, so the mean
    of the sampled velocities is 2 V; the mean speed, displacement over time, is V."""
    mean = 0.008
    with BagWriter(tmp_path / "bag") as w:
        w.add_topic("/f/drive/command", "feeder_ros/msg/DriveCommand")
        w.add_topic("/f/parts/state", "feeder_ros/msg/PartStateArray")
        command = DriveCommand(enabled=True, frequency_hz=30.0, amplitude_n=20.0)
        w.write("/f/drive/command", cdr(stamp(command, T0)), T0)
        for k in range(201):  # 4 s at 50 Hz
            t = k / 50
            w_t = 2 * math.pi * 150.0 * t
            part = PartState(
                part_id=1,
                position_m=mean * t + mean * math.sin(w_t) / (2 * math.pi * 150.0),
                velocity_mps=mean * (1.0 + math.cos(w_t)),
                on_track=True,
            )
            t_ns = T0 + k * 20 * MS
            w.write("/f/parts/state", cdr(stamp(PartStateArray(parts=[part]), t_ns)), t_ns)
    [segment] = analyze_bag(tmp_path / "bag").segments
    assert segment.speed_ground_truth_mps == pytest.approx(mean, rel=1e-9)


@pytest.mark.parametrize(("rate_hz", "given"), [(50.0, False), (997.0, True)])
def test_the_sampled_slip_fraction_is_given_only_when_the_samples_cover_the_cycle(
    tmp_path: Path, rate_hz: float, given: bool
) -> None:
    """A part slipping over [0.1, 0.35) of each 30 Hz drive cycle (slip fraction 0.25): sampled at
    50 Hz it is seen at 5 phases only, one of them slipping (0.20, wrong); sampled at 997 Hz the
    phases cover the cycle and the share slipping is the slip fraction."""
    with BagWriter(tmp_path / "bag") as w:
        w.add_topic("/f/drive/command", "feeder_ros/msg/DriveCommand")
        w.add_topic("/f/parts/state", "feeder_ros/msg/PartStateArray")
        command = DriveCommand(enabled=True, frequency_hz=30.0, amplitude_n=20.0)
        w.write("/f/drive/command", cdr(stamp(command, T0)), T0)
        for k in range(int(4 * rate_hz) + 1):  # 4 s
            t_ns = T0 + round(k * 1e9 / rate_hz)
            phase = math.fmod((t_ns - T0) * 1e-9 * 30.0, 1.0)
            slipping = 0.1 <= phase < 0.35
            part = PartState(part_id=1, position_m=0.008 * (t_ns - T0) * 1e-9, on_track=True)
            part.phase = PartState.PHASE_SLIP_FORWARD if slipping else PartState.PHASE_STICK
            w.write("/f/parts/state", cdr(stamp(PartStateArray(parts=[part]), t_ns)), t_ns)
    result = analyze_bag(tmp_path / "bag")
    [segment] = result.segments
    aliased = [p for p in result.problems if p.startswith("[aliased]")]
    if given:
        assert segment.slip_ground_truth == pytest.approx(0.25, abs=0.005)
        assert aliased == []
    else:
        assert math.isnan(segment.slip_ground_truth)
        [problem] = aliased
        assert "sampled 5 of 36 phase bins of the 30 Hz drive cycle" in problem
        assert "their share slipping, 0.20, would be that of those phases only" in problem
    assert segment.speed_ground_truth_mps == pytest.approx(0.008, rel=1e-9)  # speed: always
