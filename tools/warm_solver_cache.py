#!/usr/bin/env python3
"""Compile the package's numba kernels once, into numba's on-disk cache.

Run by `make install` (and after building the ROS workspace, whose copy of the sources has its
own cache): nodes, tests and tools then load the compiled physics engine and estimator in about a
second instead of compiling them on first use (tens of seconds for the engine, about 3 s for the
estimator on this machine type: a node that compiled at start-up stalled for that long).
"""

from __future__ import annotations

import time

from feeder_ros.estimation.calibration import Calibrator, SpeedMeasurement
from feeder_ros.estimation.part_belief import PartBelief
from feeder_ros.estimation.vehicle_estimator import VehicleEstimator
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
    # the estimator: harmonic fit, stick-slip observer, calibration's steady-speed runs
    carrier = simulate(params.with_changes(drive_frequency_hz=22.0), 2.0, 1000.0)
    estimator = VehicleEstimator()
    estimator.set_drive(22.0, 40.0, 0.0)
    for k in range(0, carrier.t_s.size, 100):
        estimator.push(carrier.t_s[k : k + 100], carrier.carrier_a_mps2[k : k + 100])
    if estimator.fit is not None:
        calibrator = Calibrator(PartBelief.prior(estimator.config.part))
        speed, _ = calibrator.predict(estimator.fit)
        calibrator.add(SpeedMeasurement(estimator.fit, max(speed, 1e-3), 1e-3, "transit"))
    print(f"solver kernels ready ({time.perf_counter() - started:.1f} s)")


if __name__ == "__main__":
    main()
