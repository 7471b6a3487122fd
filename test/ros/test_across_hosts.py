"""The plant layout: the feeder's nodes on one host, the cell controller on another.

Two network namespaces joined by a veth pair stand for the two hosts. The feeder cell (simulator,
estimator, drive interface, speed monitor) runs in one, the installed example cell controller in
the other; discovery reaches beyond localhost (``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET``) and Fast
DDS uses UDP only, so every sample crosses the veth link (the namespaces share ``/dev/shm``, which
Fast DDS's shared-memory transport would otherwise use). The test makes the namespaces and the link,
addresses only that link, and removes all of it afterwards. Every other test stays on localhost.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest
from ros_test_tools import demo_cell_file, running

BIN = Path(sys.executable).parent
NAMESPACE = "/plant/feeder_1"


@dataclass(frozen=True)
class TwoHosts:
    feeder_ns: str
    controller_ns: str
    controller_link: str


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["ip", *args], capture_output=True, text=True, check=check)


@contextmanager
def two_hosts() -> Iterator[TwoHosts]:
    """Two namespaces joined by a veth pair on a /30 of their own; removed on exit."""
    tag = f"{os.getpid() % 100000}"
    feeder_ns, controller_ns = f"feeder-{tag}-a", f"feeder-{tag}-b"
    link_a, link_b = f"fda{tag}", f"fdb{tag}"
    subnet = f"10.{200 + os.getpid() % 50}.{os.getpid() % 250}"
    made: list[str] = []
    try:
        for ns in (feeder_ns, controller_ns):
            added = _ip("netns", "add", ns, check=False)
            if added.returncode != 0:
                if not made and ("Permission" in added.stderr or "not permitted" in added.stderr):
                    pytest.skip(f"the kernel refuses network namespaces: {added.stderr.strip()}")
                raise AssertionError(f"ip netns add {ns}: {added.stderr.strip()}")
            made.append(ns)
        _ip("link", "add", link_a, "netns", feeder_ns, "type", "veth", "peer", "name", link_b,
            "netns", controller_ns)  # fmt: skip
        for ns, link, host in ((feeder_ns, link_a, 1), (controller_ns, link_b, 2)):
            _ip("-n", ns, "link", "set", "lo", "up")
            _ip("-n", ns, "addr", "add", f"{subnet}.{host}/30", "dev", link)
            _ip("-n", ns, "link", "set", link, "up")
            # discovery's multicast (239.255.0.1) leaves through the link
            _ip("-n", ns, "route", "add", "224.0.0.0/4", "dev", link)
        yield TwoHosts(feeder_ns, controller_ns, link_b)
    finally:
        for ns in made:  # deleting a namespace deletes its end of the veth pair, and the pair
            _ip("netns", "delete", ns, check=False)


def _received_bytes(ns: str, link: str) -> int:
    stats = json.loads(_ip("-n", ns, "-s", "-j", "link", "show", link).stdout)
    return int(stats[0]["stats64"]["rx"]["bytes"])


def test_a_controller_on_another_host_drives_the_feeder_and_sees_its_estimate(
    tmp_path: Path,
) -> None:
    env = dict(os.environ)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"  # beyond localhost, as between two hosts
    env["FASTDDS_BUILTIN_TRANSPORTS"] = "UDPv4"  # no shared memory between the "hosts"
    timeline = tmp_path / "timeline.json"
    with two_hosts() as hosts:
        cell = ["ip", "netns", "exec", hosts.feeder_ns, str(BIN / "feeder"), "cell",
                "--config", str(demo_cell_file(tmp_path, NAMESPACE, name="plant"))]  # fmt: skip
        controller = [
            "ip", "netns", "exec", hosts.controller_ns, str(BIN / "cell_controller"),
            "--namespace", NAMESPACE, "--hold", "4", "--timeline", str(timeline),
        ]  # fmt: skip
        with running(cell, env=env) as feeder:
            result = subprocess.run(controller, env=env, capture_output=True, text=True,
                                    timeout=400)  # fmt: skip
            assert feeder.poll() is None, feeder.output()[-3000:]
        received = _received_bytes(hosts.controller_ns, hosts.controller_link)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    steps = json.loads(timeline.read_text())
    names = [step["step"] for step in steps]
    assert "feeder sensors live" in names  # the controller received the estimate stream
    speeds = [s for s in steps if s["step"] == "speed status"]
    assert len(speeds) == 3, names
    for status in speeds[:2]:  # driving at its two targets, the feeder's parts moved
        assert status["estimated_mm_s"] is not None, status
        assert status["estimated_mm_s"] > 1.0, status
        assert status["target_mm_s"] > 0.0
    targets = [s for s in steps if s["step"] == "set_target_speed"]
    assert [t["result"] for t in targets] == ["accepted", "accepted"], targets
    assert next(s for s in steps if s["step"] == "watchdog")["tripped"] is True
    # everything the controller saw came over the link: drive state, speed status and the
    # estimate stream at their rates for well over 20 s are far more than 100 kB
    assert received > 100_000, received
