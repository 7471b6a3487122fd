"""Public simulation API of the feeder model: carrier (platform) and parts in stick-slip.

The sharp model (``stiffness_model="sharp"``) is solved exactly, event by event
(:mod:`feeder_ros.physics.exact`): no time step, the only errors are floating-point round-off
and root polishing to round-off level. ``simulate`` hands the logistic model to
:func:`feeder_ros.physics.smooth_model.simulate_smooth`.

Model (SI units), paper Eqs. 6, 7, 11-16 as read in MODEL-NOTES:

* Carrier: ``M_eq*x'' + c*x' + K(s)*cos(theta)*x = F(t) + R(t)``, ``K = K_f`` for ``s > 0`` and
  ``K_b`` for ``s < 0`` with ``s = x`` (``stiffness_switch="displacement"``, default) or ``s = x'``
  (``"velocity"``). The carrier starts at rest on the switching surface in the forward branch
  (``x''' > 0`` there). Velocity switching, Filippov convention: at ``x' = 0`` the carrier crosses
  if both branches push it the same way; it is *held* (``x' = x'' = 0``, branch code 0) while ``F +
  R`` lies between ``K_b*cos(theta)*x`` and ``K_f*cos(theta)*x``, and leaves into the branch whose
  force first lets it go.
* Coupling ``one_way`` (default): ``M_eq = M + M_p + alpha*m``
  (``FeederParameters.equivalent_mass_kg``) and ``R = 0``: the parts never act on the carrier.
  ``two_way`` (Eq. 14): ``M_eq = M + alpha*m + sum of the masses of the sticking parts``; each
  slipping part adds the reaction ``R_i = -M_i*a_i`` of the friction it receives (``a_i =
  +-mu_d*g*kappa``).
* Part (Coulomb stick-slip): sticks while ``|x''| <= mu_s*g*kappa``; slips with acceleration
  ``mu_d*g*kappa*sign(x' - u)`` (friction drags it toward the carrier's velocity); when ``u = x'``
  again it re-sticks if the stick condition holds then (two-way: with its own mass back on the
  carrier), otherwise it slips the other way.
* Positions: ``part_x_m`` and ``part_v_mps`` are in the lab frame. A part's place on the track is
  ``part_x_m - carrier_x_m`` (the track moves with the carrier); a part is put on the track at
  ``PartSpec.position_m`` and sticks. It leaves when its track position passes ``track_length_m`` (a
  sticking part keeps its track position, so parts leave only while slipping). After leaving its
  column holds ``nan`` positions/velocities and phase ``Phase.EXITED`` (-1); the exit is an event.
* Drive: :class:`~feeder_ros.physics.drive.DriveSchedule`, phase-continuous; ramps are applied as a
  fine staircase that the solver integrates exactly.

Output samples are taken at the requested times from the closed-form solution (``simulate``: exact
multiples ``k/output_rate_hz``). A sample at an event instant shows the state just after the event.

How it runs: parts of equal friction that stick together share one velocity history for ever (a
*group*; exact, not an approximation), so 1000 identical parts cost about one. With two-way
coupling, or with few groups, or in short chunks, one event loop advances carrier and groups
together. With one-way coupling, many groups and enough simulated time per call
(``FeederSimulator.parallel_min_groups``, ``march_min_work_s``) the carrier is solved alone first,
its closed-form pieces are recorded, and the groups are then marched along them independently, in
parallel (numba ``prange``); group events are expanded to one event per part.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from feeder_ros.physics.batch import simulate_many
from feeder_ros.physics.drive import DriveSchedule
from feeder_ros.physics.errors import SimulationError
from feeder_ros.physics.live_simulator import (
    FORGET_DRIVE_CHANGES_AFTER,
    FeederSimulator,
    limited_threads,
)
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.parameters import finite_number as _finite
from feeder_ros.physics.results import (
    F64,
    EventKind,
    EventLog,
    ManySummary,
    PartSpec,
    Phase,
    SimulationResult,
)
from feeder_ros.physics.smooth_model import simulate_smooth

__all__ = [
    "FORGET_DRIVE_CHANGES_AFTER",
    "EventKind",
    "EventLog",
    "FeederSimulator",
    "ManySummary",
    "PartSpec",
    "Phase",
    "SimulationError",
    "SimulationResult",
    "limited_threads",
    "simulate",
    "simulate_carrier",
    "simulate_many",
    "simulate_parts",
]


def _sample_times(duration_s: float, output_rate_hz: float) -> F64:
    duration = _finite("duration_s", duration_s, positive=True)
    rate = _finite("output_rate_hz", output_rate_hz, positive=True)
    n = math.floor(duration * rate * (1.0 + 1e-12))
    samples = np.arange(n + 1, dtype=np.float64)
    samples /= rate  # in place: the same values as arange / rate, one array less
    return samples


def simulate(
    params: FeederParameters,
    duration_s: float,
    output_rate_hz: float,
    parts: Sequence[PartSpec] = (PartSpec(),),
    drive: DriveSchedule | None = None,
) -> SimulationResult:
    """Simulate from rest for ``duration_s``; samples at ``k/output_rate_hz`` for k = 0, 1, ...

    Sharp model: exact event-driven solution. ``params.stiffness_model == "logistic"``: delegated to
    :func:`feeder_ros.physics.smooth_model.simulate_smooth` (an ODE solver on Eq. 6 + Eq. 9).
    """
    samples = _sample_times(duration_s, output_rate_hz)
    if params.stiffness_model == "logistic":
        result: SimulationResult = simulate_smooth(params, duration_s, output_rate_hz, parts, drive)
        return result
    sim = FeederSimulator(params, parts, drive)
    # the last sample (a multiple of 1/rate) may lie a round-off past duration_s: run to it
    return sim._advance(max(float(duration_s), float(samples[-1])), samples)


def simulate_carrier(
    params: FeederParameters,
    duration_s: float,
    output_rate_hz: float,
    drive: DriveSchedule | None = None,
) -> SimulationResult:
    """The carrier alone (no parts; with two-way coupling its mass is then ``M + alpha*m``)."""
    return simulate(params, duration_s, output_rate_hz, (), drive)


def simulate_parts(
    params: FeederParameters,
    duration_s: float,
    output_rate_hz: float,
    parts: Sequence[PartSpec] = (PartSpec(),),
    drive: DriveSchedule | None = None,
) -> SimulationResult:
    """Parts on the exact one-way carrier trajectory (``coupling`` forced to ``one_way``)."""
    return simulate(
        params.with_changes(coupling="one_way"), duration_s, output_rate_hz, parts, drive
    )
