#!/usr/bin/env python3
"""Compile the physics engine's numba kernels once, into numba's on-disk cache.

Run by `make install` (and after building the ROS workspace, whose copy of the sources has its
own cache): nodes, tests and tools then load the compiled solver in about a second instead of
compiling it on first use (tens of seconds on this machine type).
"""

from __future__ import annotations

import time

from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import PartSpec, simulate, simulate_many


def main() -> None:
    started = time.perf_counter()
    params = FeederParameters(drive_amplitude_n=40.0, damping_ns_per_m=200.0)
    simulate(params, 0.05, 1000.0, parts=[PartSpec(), PartSpec(position_m=0.01)])
    simulate(params.with_changes(coupling="two_way"), 0.05, 1000.0)
    # parts of distinct frictions: the parallel group march, its node tables and event kernels
    distinct = [PartSpec(static_friction=0.2 + 0.01 * i, kinetic_friction=0.1) for i in range(4)]
    simulate(params, 0.05, 1000.0, parts=distinct)
    many = [params.with_changes(drive_frequency_hz=f) for f in (20.0, 25.0, 30.0, 35.0)]
    simulate_many(many, 0.05)
    print(f"solver kernels ready ({time.perf_counter() - started:.1f} s)")


if __name__ == "__main__":
    main()
