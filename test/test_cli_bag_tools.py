"""``feeder info`` and ``feeder reindex`` on bags written here: counts read back, damage named,
exit statuses, and a cut-short bag repaired (read back by rosbags, an independent reader)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mcap.reader import make_reader
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader as RosbagsReader
from std_msgs.msg import Float64

from feeder_ros.bag import BagWriter
from feeder_ros.cli.main import main

T0 = 1_700_000_000_000_000_000


def write_bag(path: Path, n: int, **options: int) -> None:
    """``n`` messages on /imu_like (1 ms apart) and ``n // 10`` on /slow."""
    with BagWriter(path, chunk_size=2048, **options) as writer:
        writer.add_topic("/imu_like", "std_msgs/msg/Float64")
        writer.add_topic("/slow", "std_msgs/msg/Float64")
        for i in range(n):
            writer.write(
                "/imu_like", bytes(serialize_message(Float64(data=i * 0.5))), T0 + i * 10**6
            )
            if i % 10 == 0:
                writer.write("/slow", bytes(serialize_message(Float64(data=-i))), T0 + i * 10**6)


def three_file_bag(tmp_path: Path) -> tuple[Path, list[Path]]:
    """:func:`write_bag` of 300 messages split into three files of 100 ms each."""
    bag = tmp_path / "bag"
    write_bag(bag, 300, max_file_duration_ns=100 * 10**6)
    files = sorted(bag.glob("*.mcap"))
    assert len(files) == 3
    return bag, files


def test_info_counts_a_whole_bag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = tmp_path / "bag"
    write_bag(bag, 300)
    assert main(["info", str(bag)]) == 0
    text = capsys.readouterr().out
    assert "Messages:  330" in text
    assert "Duration:  0.299 s" in text
    assert "End:       2023-11-14T22:13:20.299+00:00 (1700000000.299000000 s)" in text
    lines = {line.split()[0]: line.split() for line in text.splitlines() if line.startswith("  /")}
    assert lines["/imu_like"][1:] == ["std_msgs/msg/Float64", "300", "msgs"]
    assert lines["/slow"][1:] == ["std_msgs/msg/Float64", "30", "msgs"]
    assert "DATA LOST" not in text
    assert "Problems" not in text
    assert main(["info", str(bag), "--json", "--verify"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["message_count"] == 330
    assert data["start_ns"] == T0
    assert data["end_ns"] == T0 + 299 * 10**6
    assert {t["name"]: t["message_count"] for t in data["topics"]} == {
        "/imu_like": 300,
        "/slow": 30,
    }
    assert data["data_lost"] is False
    assert data["problems"] == []


def test_info_names_lost_data_and_refuses_a_non_bag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag, files = three_file_bag(tmp_path)
    files[1].unlink()  # a split file lost: its 100 ms of recording are gone
    assert main(["info", str(bag), "--json"]) == 1
    data = json.loads(capsys.readouterr().out)
    assert data["data_lost"] is True
    kinds = [p["kind"] for p in data["problems"] if p["data_lost"]]
    assert kinds == ["missing_file", "lost_messages"]
    assert data["message_count"] == 330 - 110
    # counted: metadata.yaml lists the missing file's 110 messages (100 + 10)
    assert data["lost_messages"] == 110
    assert (data["loss"]["recorded"], data["loss"]["total_known"]) == (330, True)
    lost = {t["name"]: (t["recorded"], t["lost"]) for t in data["loss"]["topics"]}
    assert lost == {"/imu_like": (300, 100), "/slow": (30, 10)}
    assert main(["info", str(bag)]) == 1
    text = capsys.readouterr().out
    assert "Messages:  220 readable of 330 recorded: 110 LOST" in text
    assert "DATA LOST: 110 of 330 recorded messages lost (33.3 %" in text
    assert "2 problem(s) lost recorded messages" in text
    assert f"[missing_file] {files[1]}" in text
    missing = tmp_path / "nothing"
    assert main(["info", str(missing)]) == 2
    assert f"feeder info: error: no bag at {missing}" in capsys.readouterr().err
    text_file = tmp_path / "notes.mcap"
    text_file.write_text("not a recording\n")
    assert main(["info", str(text_file)]) == 2
    assert f"{text_file}: not a bag" in capsys.readouterr().err


def test_reindex_repairs_a_cut_short_bag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "bag"
    write_bag(bag, 300)
    mcap = next(bag.glob("*.mcap"))
    with mcap.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    assert len(chunks) > 4
    kept = chunks[:4]
    # the killed recorder (it writes whole chunks): the file ends after the fourth chunk, and
    # metadata.yaml is gone
    mcap.write_bytes(mcap.read_bytes()[: chunks[4].chunk_start_offset])
    (bag / "metadata.yaml").unlink()
    assert main(["info", str(bag)]) == 0  # cut short, nothing lost: the complete chunks read
    text = capsys.readouterr().out
    assert "cut short" in text
    assert "how many were recorded is unknown" in text
    readable = int(
        next(line for line in text.splitlines() if line.startswith("Messages:")).split()[1]
    )
    assert 0 < readable < 330
    last_ns = max(c.message_end_time for c in kept)
    assert main(["reindex", str(bag)]) == 0
    text = capsys.readouterr().out
    assert f"Messages:  {readable}" in text
    assert "cut short" not in text
    with RosbagsReader(bag) as reader:  # metadata.yaml and a whole file again
        assert reader.message_count == readable
        assert reader.end_time == last_ns + 1
        assert {c.topic for c in reader.connections} == {"/imu_like", "/slow"}
    assert main(["info", str(bag), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["cut_short"] is False
    assert data["message_count"] == readable


def test_reindex_leaves_a_damaged_file_and_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag, files = three_file_bag(tmp_path)
    files[1].write_bytes(b"not an mcap file at all")
    before = {p.name: p.read_bytes() for p in files}
    assert main(["reindex", str(bag)]) == 1
    text = capsys.readouterr().out
    assert "DATA LOST" in text
    assert {p.name: p.read_bytes() for p in files} == before  # nothing rewritten
    none = tmp_path / "none"
    assert main(["reindex", str(none)]) == 2
    assert f"no bag at {none}: reindex needs a bag directory" in capsys.readouterr().err
    assert main(["reindex", str(files[0])]) == 2  # a file, not a directory
    assert f"no bag at {files[0]}: reindex needs a bag directory" in capsys.readouterr().err
