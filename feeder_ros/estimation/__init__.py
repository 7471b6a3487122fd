"""Sensorless stick-slip vehicle estimator (ROS-free core).

From the carrier's measured acceleration alone: a drift-free carrier velocity
(:mod:`~feeder_ros.estimation.carrier_velocity`), the stick-slip motion of a nominal part
(:mod:`~feeder_ros.estimation.stick_slip_observer`) and the streaming estimator with window
statistics, confidences and status codes (:mod:`~feeder_ros.estimation.vehicle_estimator`).
"""

from feeder_ros.estimation.carrier_velocity import (
    CarrierFitError,
    HarmonicFit,
    estimate_frequency,
    fit_harmonics,
    refine_frequency,
    select_period_order,
)
from feeder_ros.estimation.stick_slip_observer import (
    PHASE_SLIP_BACKWARD,
    PHASE_SLIP_FORWARD,
    PHASE_STICK,
    ObserverOutput,
    PartModel,
    StickSlipObserver,
)
from feeder_ros.estimation.vehicle_estimator import (
    EstimateTrace,
    EstimatorConfig,
    Status,
    VehicleEstimate,
    VehicleEstimator,
)

__all__ = [
    "PHASE_SLIP_BACKWARD",
    "PHASE_SLIP_FORWARD",
    "PHASE_STICK",
    "CarrierFitError",
    "EstimateTrace",
    "EstimatorConfig",
    "HarmonicFit",
    "ObserverOutput",
    "PartModel",
    "Status",
    "StickSlipObserver",
    "VehicleEstimate",
    "VehicleEstimator",
    "estimate_frequency",
    "fit_harmonics",
    "refine_frequency",
    "select_period_order",
]
