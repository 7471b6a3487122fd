"""Bags never hide loss: a truncated bag's lost messages are counted (in total and per topic) and
``feeder info`` / ``feeder analyze`` / ``feeder reindex`` exit 1 as their --help says.

Bags are written here, read whole by rosbags (an independent reader: what was recorded), then cut
mid-chunk or at a chunk boundary; what is still readable is counted independently with the mcap
package's stream reader (the messages of the chunks before the cut).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml
import zstandard
from bag.test_analysis import write_feeder_bag
from mcap.reader import make_reader
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader as RosbagsReader
from std_msgs.msg import Float64

from feeder_ros.bag import Bag, BagWriter, bag_info
from feeder_ros.bag.loss import LOST_KEY
from feeder_ros.cli.main import main

T0 = 1_780_000_000_000_000_000
MS = 1_000_000


def write_bag(path: Path, n: int, compression: str = "zstd", chunk_size: int = 4096) -> None:
    """``n`` messages on /fast (1 ms apart) and one in ten on /slow."""
    with BagWriter(path, compression=compression, chunk_size=chunk_size) as writer:
        writer.add_topic("/fast", "std_msgs/msg/Float64")
        writer.add_topic("/slow", "std_msgs/msg/Float64")
        for i in range(n):
            data = bytes(serialize_message(Float64(data=i * 0.5)))
            writer.write("/fast", data, T0 + i * MS)
            if i % 10 == 0:
                writer.write("/slow", data, T0 + i * MS)


def recorded(bag: Path) -> dict[str, int]:
    """Messages per topic, read one by one by rosbags from the whole bag."""
    counts: dict[str, int] = {}
    with RosbagsReader(bag) as reader:
        for connection, _, _ in reader.messages():
            counts[connection.topic] = counts.get(connection.topic, 0) + 1
    return counts


def readable(mcap: Path) -> dict[str, int]:
    """Messages per topic the mcap package's stream reader reads from a (cut) file: those of the
    chunks before the cut."""
    topics: dict[int, str] = {}
    counts: dict[str, int] = {}
    with mcap.open("rb") as stream:
        try:
            for record in StreamReader(stream).records:
                if isinstance(record, Channel):
                    topics[record.id] = record.topic
                elif isinstance(record, Message):
                    topic = topics[record.channel_id]
                    counts[topic] = counts.get(topic, 0) + 1
        except Exception:  # the cut: what came before it is what a reader gets
            pass
    return counts


def cut(mcap: Path, where: str, chunk: int = 6) -> int:
    """Cut the file three quarters into its ``chunk``-th chunk, or just before it (at the
    boundary after the previous chunk's message indexes); returns the new size."""
    with mcap.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    index = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)[chunk]
    size = index.chunk_start_offset + (index.chunk_length * 3 // 4 if where == "mid_chunk" else 0)
    mcap.write_bytes(mcap.read_bytes()[:size])
    return size


@pytest.mark.parametrize("where", ["mid_chunk", "boundary"])
def test_a_truncated_bag_counts_its_lost_messages(
    tmp_path: Path, where: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """metadata.yaml (rewritten when the bag was closed) counts what was recorded: the messages
    past the cut are lost, counted in total and per topic, and ``feeder info`` exits 1."""
    bag = tmp_path / "bag"
    write_bag(bag, 2000)
    before = recorded(bag)
    assert before == {"/fast": 2000, "/slow": 200}
    cut(bag / "bag_0.mcap", where)
    after = readable(bag / "bag_0.mcap")
    lost = {t: before[t] - after.get(t, 0) for t in before}
    total = sum(lost.values())
    assert 0 < total < 2200

    assert main(["info", str(bag), "--json"]) == 1
    data = json.loads(capsys.readouterr().out)
    assert data["message_count"] == sum(after.values())
    assert data["lost_messages"] == total
    assert data["data_lost"] is True
    loss = data["loss"]
    assert (loss["recorded"], loss["readable"], loss["total_known"]) == (2200, 2200 - total, True)
    assert {t["name"]: (t["recorded"], t["lost"]) for t in loss["topics"]} == {
        t: (before[t], lost[t]) for t in before
    }
    kinds = [p["kind"] for p in data["problems"] if p["data_lost"]]
    assert kinds == (["cut_chunk", "lost_messages"] if where == "mid_chunk" else ["lost_messages"])

    assert main(["info", str(bag)]) == 1
    text = capsys.readouterr().out
    assert f"Messages:  {2200 - total} readable of 2200 recorded: {total} LOST" in text
    assert f"/fast  std_msgs/msg/Float64  {after['/fast']} msgs of 2000 recorded: " in text
    assert f"DATA LOST: {total} of 2200 recorded messages lost (" in text
    assert "counted from metadata.yaml" in text


@pytest.mark.parametrize("compression", ["none", "zstd"])
def test_a_truncated_bag_without_metadata_says_the_total_is_unknown(
    tmp_path: Path, compression: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """No metadata.yaml and no summary: a cut through a chunk still loses what the chunk held
    (counted from its readable part: a lower bound; exit 1); a cut at a chunk boundary, as a
    killed recorder leaves, loses nothing counted, and the total is reported unknown (exit 0)."""
    for where in ("mid_chunk", "boundary"):
        bag = tmp_path / where
        # chunks of 256 KiB: zstd compresses them in three blocks (of 128 KiB of records at
        # most), the first of which is whole in the first three quarters of a cut chunk (and so
        # are records of an uncompressed one)
        write_bag(bag, 20_000, compression=compression, chunk_size=256 << 10)
        before = recorded(bag)
        (bag / "metadata.yaml").unlink()
        cut(bag / f"{where}_0.mcap", where, chunk=2)
        after = readable(bag / f"{where}_0.mcap")
        truly_lost = sum(before.values()) - sum(after.values())
        status = main(["info", str(bag), "--json"])
        data = json.loads(capsys.readouterr().out)
        loss = data["loss"]
        assert data["message_count"] == sum(after.values())
        assert loss["total_known"] is False
        assert loss["unknown_because"] == [
            f"{where}_0.mcap ends without a summary and metadata.yaml does not count it"
        ]
        if where == "mid_chunk":
            assert status == 1
            # the complete message records in the cut chunk's first half: some, not all, lost
            assert 0 < data["lost_messages"] < truly_lost
            main(["info", str(bag)])
            text = capsys.readouterr().out
            assert f"({data['lost_messages']} at least LOST)" in text
            assert f"DATA LOST: at least {data['lost_messages']} recorded message(s) lost" in text
        else:
            assert status == 0
            assert data["lost_messages"] == 0
            main(["info", str(bag)])
            text = capsys.readouterr().out
            assert "how many messages were recorded (and lost) is unknown" in text


def test_reindex_keeps_the_count_of_what_was_lost(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A repaired bag still says what it lost: reindex finishes the cut file (rosbags reads it
    again) and keeps the lost count in metadata.yaml's custom_data; info exits 1 after it."""
    bag = tmp_path / "bag"
    write_bag(bag, 2000)
    cut(bag / "bag_0.mcap", "mid_chunk")
    kept = sum(readable(bag / "bag_0.mcap").values())
    lost = 2200 - kept
    assert main(["reindex", str(bag)]) == 1
    assert f"{lost} of 2200 recorded messages lost" in capsys.readouterr().out
    with RosbagsReader(bag) as reader:
        assert reader.message_count == kept
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == kept
    assert meta["custom_data"][LOST_KEY] == str(lost)
    assert main(["info", str(bag), "--json"]) == 1
    data = json.loads(capsys.readouterr().out)
    assert data["cut_short"] is False
    assert (data["lost_messages"], data["loss"]["lost_before_reindex"]) == (lost, lost)
    assert main(["reindex", str(bag)]) == 1  # again: the same count, not twice it
    capsys.readouterr()
    info = bag_info(Bag(bag, warn=False))
    assert info.loss is not None
    assert info.loss.lost == lost


@pytest.mark.parametrize("frame_checksums", [False, True], ids=["crc32", "zstd-checksums"])
def test_verify_says_what_it_checked(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    frame_checksums: bool,
) -> None:
    """Without --verify, info counts from the message indexes and says what --verify adds; with
    it, every chunk is decompressed and checked and every message decoded: a message cut before
    its last field is found only then (and is lost data: exit 1). Chunks are checked by their
    CRC-32 (as mcap's writer writes them), or by zstd's frame checksum where the frame has one
    (other writers': zstd verifies it while decompressing, and the CRC is not computed again)."""
    if frame_checksums:
        compressor = zstandard.ZstdCompressor(write_checksum=True)
        monkeypatch.setattr("mcap.writer.zstandard.compress", compressor.compress)
    bag = tmp_path / "bag"
    with BagWriter(bag, chunk_size=1024) as writer:
        writer.add_topic("/fast", "std_msgs/msg/Float64")
        for i in range(300):
            data = bytes(serialize_message(Float64(data=i * 0.5)))
            writer.write("/fast", data[:-4] if i == 123 else data, T0 + i * MS)
    with (bag / "bag_0.mcap").open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    chunks = len(summary.chunk_indexes)
    assert main(["info", str(bag)]) == 0
    text = capsys.readouterr().out
    assert f"Checked:   {chunks} chunk(s) in 1 file(s), counted from their message indexes" in text
    assert "--verify also decompresses every chunk, checks its CRC" in text
    assert main(["info", str(bag), "--verify"]) == 1
    text = capsys.readouterr().out
    crc, frames = (0, chunks) if frame_checksums else (chunks, 0)
    assert (
        f"Verified:  {chunks} chunk(s) in 1 file(s): {chunks} decompressed, {crc} CRC-32 and "
        f"{frames} zstd checksum(s) checked, 300 message record(s) checked against their index, "
        "299 message(s) decoded"
    ) in text
    assert "[malformed_message]" in text
    assert "1 std_msgs/msg/Float64 message(s) end before their last field" in text


def test_analyze_counts_the_loss_of_a_truncated_feeder_bag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``feeder analyze`` of a truncated feeder bag: results from what was read, the lost
    messages counted (not ``lost_s = 0``), exit 1."""
    for where in ("mid_chunk", "boundary"):
        bag = tmp_path / where
        write_feeder_bag(bag, chunk_size=8192, extras=False)
        total = sum(recorded(bag).values())
        cut(bag / f"{where}_0.mcap", where, chunk=60)
        lost = total - sum(readable(bag / f"{where}_0.mcap").values())
        out = tmp_path / f"out_{where}"
        assert main(["analyze", str(bag), "--output", str(out)]) == 1
        captured = capsys.readouterr()
        assert f"DATA LOST: {lost} of {total} recorded messages lost" in captured.out
        assert f"{bag}: data lost ({lost} of {total} recorded messages lost" in captured.err
        (document,) = json.loads((out / "analysis.json").read_text())["bags"]
        assert document["lost_messages"] == lost
        assert document["loss"]["recorded"] == total
        assert "data lost" in (out / "comparison.csv").read_text()
