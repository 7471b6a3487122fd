"""Benchmark of the bag core and ``feeder analyze`` (not a timed test).

One run, on this machine:

* decode throughput on ONE generated bag of sensor_msgs/Imu plus feeder_ros/CarrierState messages
  (1 kHz each, interleaved, zstd chunks as ``feeder record`` writes them; >= 1 million Imu):
  ``feeder_ros.bag.read_tables`` (every field of both types, vectorised into numpy columns) against
  per-message decoders reading the same file: the ``mcap`` reader with ``mcap-ros2-support`` and
  with ``mcap-ros2-support-fast`` decoder factories, and ``rosbags`` (``Reader`` +
  ``Typestore.deserialize_cdr``). The per-message decoders are timed on the first ``--sample``
  messages (the whole bag would take minutes); their decoded values are checked against ours. The
  ratio column is each row's throughput over the fastest baseline; the target for ours is >= 3x.
* one hour of a 1 kHz feeder (IMU + CarrierState + VehicleEstimate, 10.8 million messages; a drive
  frequency sweep in six 10-minute steps) analysed END TO END by ``feeder analyze BAG --output DIR``
  in a child process: wall time (target < 10 s), CPU time and peak memory (``os.wait4`` rusage).

Generated bags are cached in ``--cache`` (default ``$TMPDIR/feeder_bench_bag``) and reused.
Usage: ``python bench/bench_bag.py [--quick] [--output FILE.md] [--sample N] [--cache DIR]``.
``--quick`` is a short smoke run (small bags); its numbers mean nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from feeder_ros.bag import BagWriter, iter_messages, read_tables, ros2msg_schema  # noqa: E402

IMU = "sensor_msgs/msg/Imu"
STATE = "feeder_ros/msg/CarrierState"
ESTIMATE = "feeder_ros/msg/VehicleEstimate"
T0 = 1_760_000_000_000_000_000
POOL = 997  # distinct message bodies per type (stamps are patched per message)
SWEEP_HZ = (26.0, 27.0, 28.0, 29.0, 30.0, 31.0)
SWEEP_AMPLITUDE_N = 40.0
_STAMP = struct.Struct("<iI")  # header.stamp right after the 4-byte CDR encapsulation header


def speed_at(frequency_hz: float) -> float:
    """The estimator speed written for a sweep step (any smooth function of f will do)."""
    return 1e-3 * (frequency_hz - 25.0)


# ------------------------------------------------------------------------------ bag generation


def _pools(rng: np.random.Generator) -> dict[str, Any]:
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Imu

    from feeder_ros.msg import CarrierState, VehicleEstimate

    def imu(k: int) -> bytes:
        m = Imu()
        m.header.frame_id = "imu_link"
        m.linear_acceleration.x = float(rng.normal() * 10.0)
        m.linear_acceleration.z = 9.81 + float(rng.normal() * 0.01)
        m.angular_velocity.z = float(rng.normal())
        return bytes(serialize_message(m))

    def state(k: int, f: float, a: float) -> bytes:
        m = CarrierState()
        m.header.frame_id = "carrier"
        m.displacement_m = float(rng.normal() * 1e-4)
        m.velocity_mps = float(rng.normal() * 0.02)
        m.acceleration_mps2 = float(rng.normal() * 10.0)
        m.stiffness_branch = 1 if k % 2 else -1
        m.drive_frequency_hz, m.drive_amplitude_n = f, a
        m.drive_force_n = float(rng.normal() * a)
        return bytes(serialize_message(m))

    def estimate(k: int, f: float) -> bytes:
        m = VehicleEstimate()
        m.header.frame_id = "carrier"
        m.part_velocity_mps = float(rng.normal() * 0.01)
        m.mean_speed_mps = speed_at(f)
        m.slip_fraction = 0.5
        m.status_message = "ok"
        return bytes(serialize_message(m))

    return {
        "imu": [bytearray(imu(k)) for k in range(POOL)],
        "state": {
            f: [bytearray(state(k, f, SWEEP_AMPLITUDE_N)) for k in range(POOL)] for f in SWEEP_HZ
        },
        "estimate": {f: [bytearray(estimate(k, f)) for k in range(POOL)] for f in SWEEP_HZ},
    }


def _cached(cache: Path, name: str, key: str, make: Callable[[Path], None]) -> Path:
    path = cache / name
    marker = cache / f"{name}.key"
    if path.is_dir() and marker.is_file() and marker.read_text() == key:
        return path
    shutil.rmtree(path, ignore_errors=True)
    started = time.perf_counter()
    make(path)
    marker.write_text(key)
    print(f"generated {path} in {time.perf_counter() - started:.1f} s", file=sys.stderr)
    return path


def write_decode_bag(path: Path, n: int) -> None:
    """n Imu + n CarrierState at 1 kHz, interleaved (one drive setting)."""
    pools = _pools(np.random.default_rng(1))
    imu, state = pools["imu"], pools["state"][SWEEP_HZ[0]]
    with BagWriter(path) as writer:
        writer.add_topic("/feeder/imu", IMU)
        writer.add_topic("/feeder/carrier/state", STATE)
        write, pack = writer.write, _STAMP.pack_into
        for i in range(n):
            t = T0 + i * 1_000_000
            sec, nsec = divmod(t, 1_000_000_000)
            body = imu[i % POOL]
            pack(body, 4, sec, nsec)
            write("/feeder/imu", bytes(body), t)
            body = state[i % POOL]
            pack(body, 4, sec, nsec)
            write("/feeder/carrier/state", bytes(body), t + 1000)


def write_hour_bag(path: Path, seconds: int) -> None:
    """``seconds`` of a 1 kHz feeder: IMU, carrier state and estimate; a six-step sweep."""
    pools = _pools(np.random.default_rng(2))
    imu = pools["imu"]
    n = seconds * 1000
    step = -(-n // len(SWEEP_HZ))
    with BagWriter(path, max_file_size=1 << 30) as writer:
        writer.add_topic("/feeder/imu", IMU)
        writer.add_topic("/feeder/carrier/state", STATE)
        writer.add_topic("/feeder/estimate", ESTIMATE)
        write, pack = writer.write, _STAMP.pack_into
        for i in range(n):
            f = SWEEP_HZ[i // step]
            state, estimate = pools["state"][f], pools["estimate"][f]
            t = T0 + i * 1_000_000
            sec, nsec = divmod(t, 1_000_000_000)
            j = i % POOL
            for topic, body, dt in (
                ("/feeder/imu", imu[j], 0),
                ("/feeder/carrier/state", state[j], 1000),
                ("/feeder/estimate", estimate[j], 2000),
            ):
                pack(body, 4, sec, nsec)
                write(topic, bytes(body), t + dt)


# ------------------------------------------------------------------------------ decoders


@dataclass
class Decoded:
    name: str
    messages: int
    wall_s: float
    cpu_s: float
    imu_x: list[float]  # linear_acceleration.x of the Imu messages decoded, in order
    state_v: list[float]  # velocity_mps of the CarrierState messages decoded, in order

    @property
    def rate(self) -> float:
        """Messages per CPU second of this process (robust against other load on the machine)."""
        return self.messages / self.cpu_s


def decode_ours(path: Path) -> tuple[Decoded, np.ndarray, np.ndarray]:
    started, cpu = time.perf_counter(), time.process_time()
    n = 0
    xs: list[np.ndarray] = []
    vs: list[np.ndarray] = []
    for batch in read_tables(path, {IMU: None, STATE: None}):  # every field
        n += len(batch)
        if batch.type == IMU:
            xs.append(batch["linear_acceleration.x"])
        else:
            vs.append(batch["velocity_mps"])
    wall, cpu = time.perf_counter() - started, time.process_time() - cpu
    x, v = np.concatenate(xs), np.concatenate(vs)
    return Decoded("feeder_ros.bag read_tables (all fields)", n, wall, cpu, [], []), x, v


def decode_ours_selected(path: Path) -> Decoded:
    """What an analysis reads: the stamp and a few fields of each type."""
    started, cpu = time.perf_counter(), time.process_time()
    n = 0
    fields = {
        IMU: ["header.stamp", "linear_acceleration"],
        STATE: ["header.stamp", "displacement_m", "velocity_mps", "drive_frequency_hz"],
    }
    for batch in read_tables(path, fields):
        n += len(batch)
    wall, cpu = time.perf_counter() - started, time.process_time() - cpu
    return Decoded("feeder_ros.bag read_tables (stamp + 3 fields)", n, wall, cpu, [], [])


def decode_mcap(path: Path, factory: Any, name: str, sample: int) -> Decoded:
    from mcap.reader import make_reader

    xs: list[float] = []
    vs: list[float] = []
    n = 0
    started, cpu = time.perf_counter(), time.process_time()
    for file in sorted(path.glob("*.mcap")):
        with file.open("rb") as stream:
            reader = make_reader(stream, decoder_factories=[factory])
            for _, channel, _, message in reader.iter_decoded_messages(log_time_order=False):
                if channel.topic.endswith("imu"):
                    xs.append(message.linear_acceleration.x)
                else:
                    vs.append(message.velocity_mps)
                n += 1
                if n >= sample:
                    break
        if n >= sample:
            break
    return Decoded(name, n, time.perf_counter() - started, time.process_time() - cpu, xs, vs)


def decode_rosbags(path: Path, sample: int) -> Decoded:
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    text = (REPO / "msg" / "CarrierState.msg").read_text(encoding="utf-8")
    store.register(get_types_from_msg(text, STATE))
    xs: list[float] = []
    vs: list[float] = []
    n = 0
    started, cpu = time.perf_counter(), time.process_time()
    with Reader(path) as reader:
        for connection, _, raw in reader.messages():
            message = store.deserialize_cdr(raw, connection.msgtype)
            if connection.msgtype == IMU:
                xs.append(message.linear_acceleration.x)
            else:
                vs.append(message.velocity_mps)
            n += 1
            if n >= sample:
                break
    wall, cpu = time.perf_counter() - started, time.process_time() - cpu
    return Decoded("rosbags Reader + deserialize_cdr", n, wall, cpu, xs, vs)


def raw_sample(path: Path, sample: int) -> list[tuple[str, bytes]]:
    """The first ``sample`` messages as (type, CDR bytes), in file order."""
    out: list[tuple[str, bytes]] = []
    for message in iter_messages(path):
        out.append((message.type, message.data))
        if len(out) >= sample:
            break
    return out


def decode_only(raws: list[tuple[str, bytes]], name: str, decoder: Callable[[str], Any]) -> Decoded:
    """Per-message decoding of CDR bytes already in memory (no file reading)."""
    decoders = {kind: decoder(kind) for kind in {kind for kind, _ in raws}}
    xs: list[float] = []
    vs: list[float] = []
    started, cpu = time.perf_counter(), time.process_time()
    for kind, data in raws:
        message = decoders[kind](data)
        if kind == IMU:
            xs.append(message.linear_acceleration.x)
        else:
            vs.append(message.velocity_mps)
    wall, cpu = time.perf_counter() - started, time.process_time() - cpu
    return Decoded(name, len(raws), wall, cpu, xs, vs)


def mcap_decoder(factory: Any) -> Callable[[str], Any]:
    from mcap.records import Schema

    def make(kind: str) -> Any:
        schema = Schema(
            id=1 if kind == IMU else 2,
            name=kind,
            encoding="ros2msg",
            data=ros2msg_schema(kind).encode(),
        )
        return factory.decoder_for("cdr", schema)

    return make


def rosbags_decoder() -> Callable[[str], Any]:
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    text = (REPO / "msg" / "CarrierState.msg").read_text(encoding="utf-8")
    store.register(get_types_from_msg(text, STATE))
    return lambda kind: lambda data: store.deserialize_cdr(data, kind)


def check_values(row: Decoded, x: np.ndarray, v: np.ndarray) -> None:
    """The baseline decoded the same values as ours, message for message."""
    same = np.array_equal(np.asarray(row.imu_x), x[: len(row.imu_x)]) and np.array_equal(
        np.asarray(row.state_v), v[: len(row.state_v)]
    )
    if not same:
        raise SystemExit(f"{row.name}: decoded values differ from feeder_ros.bag")


# ------------------------------------------------------------------------------ analysis


@dataclass
class Analysed:
    wall_s: float
    cpu_s: float
    max_rss_mb: float
    document: dict[str, Any]
    stdout: str


# Started by a fresh, small interpreter: a child forked from this (large) benchmark process would
# inherit its peak RSS (Linux keeps the high-water mark across exec).
_LAUNCHER = """
import json, os, sys, time
out = open(sys.argv[1], "w")
actions = [(os.POSIX_SPAWN_DUP2, out.fileno(), 1)]
started = time.perf_counter()
pid = os.posix_spawn(sys.executable, [sys.executable, *sys.argv[2:]], os.environ,
                     file_actions=actions)
_, status, usage = os.wait4(pid, 0)
wall = time.perf_counter() - started
print(json.dumps({"wall_s": wall, "code": os.waitstatus_to_exitcode(status),
                  "cpu_s": usage.ru_utime + usage.ru_stime, "max_rss_kb": usage.ru_maxrss}))
"""


def analyse_in_child(bag: Path, out: Path) -> Analysed:
    """``feeder analyze`` in a child process: its wall time, CPU time and peak RSS."""
    log = out / "stdout.txt"
    command = [sys.executable, "-c", _LAUNCHER, str(log), "-m", "feeder_ros.cli.main", "analyze"]
    completed = subprocess.run(
        [*command, str(bag), "--output", str(out)], capture_output=True, text=True, check=False
    )
    if completed.returncode != 0 or not completed.stdout.strip():
        raise SystemExit(f"launcher failed:\n{completed.stderr}")
    result = json.loads(completed.stdout.strip().splitlines()[-1])
    if result["code"] != 0:
        raise SystemExit(f"feeder analyze failed ({result['code']}):\n{completed.stderr}")
    document = json.loads((out / "analysis.json").read_text())
    return Analysed(
        result["wall_s"],
        result["cpu_s"],
        result["max_rss_kb"] / 1024.0,
        document,
        log.read_text(),
    )


# ------------------------------------------------------------------------------ report


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--quick", action="store_true", help="short smoke run")
    parser.add_argument("--output", type=Path, help="also write the markdown report here")
    parser.add_argument("--sample", type=int, help="messages per baseline decoder")
    parser.add_argument(
        "--cache",
        type=Path,
        default=Path(tempfile.gettempdir()) / "feeder_bench_bag",
        help="where generated bags are kept",
    )
    args = parser.parse_args()
    n_decode = 20_000 if args.quick else 1_000_000
    hour_s = 12 if args.quick else 3600
    sample = args.sample or (10_000 if args.quick else 200_000)
    args.cache.mkdir(parents=True, exist_ok=True)

    decode_bag = _cached(
        args.cache, f"decode_{n_decode}", f"v2 {n_decode}", lambda p: write_decode_bag(p, n_decode)
    )
    hour_bag = _cached(
        args.cache, f"hour_{hour_s}", f"v2 {hour_s}", lambda p: write_hour_bag(p, hour_s)
    )
    size_mb = sum(f.stat().st_size for f in decode_bag.glob("*.mcap")) / 1e6
    hour_mb = sum(f.stat().st_size for f in hour_bag.glob("*.mcap")) / 1e6

    import mcap_ros2.decoder
    import mcap_ros2_support_fast

    ours, x, v = decode_ours(decode_bag)
    rows = [ours]
    selected = decode_ours_selected(decode_bag)
    for factory, name in (
        (mcap_ros2.decoder.DecoderFactory(), "mcap + mcap-ros2-support 0.6.0"),
        (mcap_ros2_support_fast.DecoderFactory(), "mcap + mcap-ros2-support-fast 0.8.0"),
    ):
        rows.append(decode_mcap(decode_bag, factory, name, sample))
    rows.append(decode_rosbags(decode_bag, sample))
    raws = raw_sample(decode_bag, sample)
    only = [
        decode_only(
            raws, "mcap-ros2-support 0.6.0", mcap_decoder(mcap_ros2.decoder.DecoderFactory())
        ),
        decode_only(
            raws,
            "mcap-ros2-support-fast 0.8.0",
            mcap_decoder(mcap_ros2_support_fast.DecoderFactory()),
        ),
        decode_only(raws, "rosbags deserialize_cdr", rosbags_decoder()),
    ]
    for row in rows[1:] + only:
        check_values(row, x, v)
    fastest = max(r.rate for r in rows[1:])
    fastest_only = max(r.rate for r in only)

    with tempfile.TemporaryDirectory() as out:
        analysed = analyse_in_child(hour_bag, Path(out))
    [bag] = analysed.document["bags"]
    freqs = [s["frequency_hz"] for s in bag["segments"]]
    speeds = [s["speed_estimate_mps"] for s in bag["segments"]]
    expected = list(SWEEP_HZ)
    sweep_ok = freqs == expected and np.allclose(speeds, [speed_at(f) for f in expected])
    messages = sum(bag["messages"].values())

    lines = [
        "### Bag decoding and analysis",
        "",
        f"`python bench/bench_bag.py{' --quick' if args.quick else ''}` on {platform.machine()}, "
        f"{os.cpu_count()} cores, Python {platform.python_version()}, numpy {np.__version__}.",
        "",
        f"#### Decode throughput: {n_decode:,} Imu + {n_decode:,} CarrierState "
        f"({size_mb:.1f} MB, zstd chunks of 1 MiB)",
        "",
        f"Ours decodes the whole bag into numpy columns (every field); each per-message decoder "
        f"reads and decodes the first {sample:,} messages of the same file (values checked equal "
        "to ours). Throughput is messages per CPU second of the benchmark process (other load "
        "on the machine shows in the wall times only); ratio: over the fastest baseline's "
        "(target for ours: >= 3x).",
        "",
        "| decoder | messages | wall [s] | CPU [s] | messages per CPU s | ratio vs fastest |",
        "| --- | ---: | ---: | ---: | ---: | ---: |",
    ]
    for row in [ours, selected, *rows[1:]]:
        lines.append(
            f"| {row.name} | {row.messages:,} | {row.wall_s:.3f} | {row.cpu_s:.3f} | "
            f"{row.rate:,.0f} | {row.rate / fastest:.2f}x |"
        )
    lines += [
        "",
        f"Decoders alone, on the same first {sample:,} messages as CDR bytes already in memory "
        "(no file reading or decompression; ours above includes both):",
        "",
        "| decoder alone | messages | wall [s] | CPU [s] | messages per CPU s | ours vs it |",
        "| --- | ---: | ---: | ---: | ---: | ---: |",
    ]
    for row in only:
        lines.append(
            f"| {row.name} | {row.messages:,} | {row.wall_s:.3f} | {row.cpu_s:.3f} | "
            f"{row.rate:,.0f} | {ours.rate / row.rate:.2f}x |"
        )
    lines += [
        "",
        f"**feeder_ros.bag vs fastest baseline: {ours.rate / fastest:.1f}x** "
        f"({'meets' if ours.rate / fastest >= 3 else 'MISSES'} the 3x target)",
        "",
        f"feeder_ros.bag (reading included) vs the fastest decoder alone: "
        f"{ours.rate / fastest_only:.1f}x",
        "",
        f"#### End to end: {hour_s} s of a 1 kHz feeder through `feeder analyze`",
        "",
        f"{messages:,} feeder messages analysed ({hour_mb:.0f} MB bag, plus "
        f"{hour_s * 1000:,} Imu messages skipped by type); a sweep of "
        f"{len(SWEEP_HZ)} drive frequencies; CSV, JSON, PNG and HTML written. One child process "
        "(`python -m feeder_ros.cli.main analyze BAG --output DIR`), measured from outside.",
        "",
        "| wall [s] | CPU [s] | peak RSS [MB] | segments found | sweep values correct | target |",
        "| ---: | ---: | ---: | ---: | --- | --- |",
        f"| {analysed.wall_s:.2f} | {analysed.cpu_s:.2f} | {analysed.max_rss_mb:.0f} | "
        f"{len(freqs)} | {'yes' if sweep_ok else 'NO'} | < 10 s: "
        f"{'met' if analysed.wall_s < 10 else 'MISSED'} |",
        "",
    ]
    report = "\n".join(lines)
    print(report)
    if args.output is not None:
        args.output.write_text(report + "\n", encoding="utf-8")
    return 0 if sweep_ok else 1


if __name__ == "__main__":
    sys.exit(main())
