"""Closed-loop part speed in target-speed mode: trim the amplitude on a trusted estimate (ROS-free).

The speed model gives the set point for a target speed (feed-forward); a real feeder differs from
its model (springs, load, friction), so the speed it reaches is off by as much as the model is.
:class:`SpeedTrim` closes the loop on the sensorless estimate once the estimate can be trusted:

* A reading counts only when it is a valid mean speed (finite, with a finite standard uncertainty
  no larger than ``max_uncertainty`` of the target: an uncalibrated part model's wide interval
  would steer the drive by its own bias) and its window lies wholly after the last set point was
  reached (``window_s`` before its stamp is after the ramp's end): a reading from the previous
  setting says nothing about this one.
* Each counted reading moves the amplitude once, in proportion: ``A *= 1 + gain * e / s`` with
  the relative error ``e = (target - speed) / target`` and the speed's sensitivity to the
  amplitude ``s = d ln v / d ln A`` at the set point, from the speed model (1 when the model
  cannot say; held within :data:`SENSITIVITY_RANGE`: near the slip threshold the table's slope
  is steep or flat over a few per cent only). On the demo's table ``s`` is about 0.85 where the
  speed is 15 mm/s, on its mismatched plant about 0.65; assuming 1 there (and a gain of 0.6)
  corrected 40 % of the error per step, and the demo's first target took six steps. The step is
  limited to ``max_step`` relative; no step while
  ``|e|`` lies within the ``deadband`` or within the reading's own relative uncertainty (the loop
  would chase the estimate's noise). The next step waits for a reading of the new setting, so
  the loop cannot run away from a lagging estimate, and the drive's limits and ramps bound every
  step (the caller applies the amplitude through the controller).
* **Calibration first.** The estimator calibrates its part model from sensor transits taken at
  one steady setting; a step voids every transit in flight (a transit takes distance/speed, 5.7 s
  at the demo's 15 mm/s). Once the cell has shown that it times transits (the calibration used
  one), each new setting is held until a transit of it has been used, at most ``transit_wait_s``:
  the next step then rests on an estimate the plant itself has checked at this setting, instead
  of voiding the data that would check it. Why every time, not only until "calibrated": the
  transits at the demo's points fix the slip deceleration (to 8-13 % after 2-5 transits) but
  leave the stick limit at its prior 30 %; it is the speed at the point in use that they pin down.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from feeder_ros.physics.parameters import ParameterError, is_number

__all__ = ["SENSITIVITY_RANGE", "SpeedTrim", "TrimSettings"]

#: the amplitude sensitivity a step assumes is held within this range
SENSITIVITY_RANGE = (0.3, 3.0)


@dataclass(frozen=True)
class TrimSettings:
    gain: float = 0.8  #: fraction of the relative error corrected per step
    max_step: float = 0.15  #: largest relative amplitude change per step
    deadband: float = 0.005  #: relative errors below this are left alone
    max_uncertainty: float = 0.03  #: readings less sure than this (relative to target) are ignored
    transit_wait_s: float = 20.0  #: longest hold for a calibrating transit (0: never hold)

    def __post_init__(self) -> None:
        for name in ("gain", "max_step", "max_uncertainty"):
            value = getattr(self, name)
            if not (is_number(value) and math.isfinite(value) and 0.0 < value <= 2.0):
                raise ParameterError(f"speed trim {name}={value!r} must be in (0, 2]")
        if not (is_number(self.deadband) and 0.0 <= self.deadband < 1.0):
            raise ParameterError(f"speed trim deadband={self.deadband!r} must be in [0, 1)")
        if not (is_number(self.transit_wait_s) and 0.0 <= self.transit_wait_s <= 600.0):
            raise ParameterError(
                f"speed trim transit_wait_s={self.transit_wait_s!r} must be in [0, 600] s"
            )


class SpeedTrim:
    """See the module docstring; the caller supplies times (the node clock)."""

    def __init__(self, settings: TrimSettings | None = None) -> None:
        self.settings = settings if settings is not None else TrimSettings()
        self._settled_s = math.inf
        self.steps = 0
        self.last_note = "no target"
        self._transit_s = -math.inf  # when the calibration last used a transit (-inf: never)

    def setting_changed(self, reached_s: float) -> None:
        """A new set point (a target, a trim step, a restart) is reached at ``reached_s``:
        readings must start after it."""
        self._settled_s = reached_s

    def transit_used(self, stamp_s: float) -> None:
        """The estimator's calibration used a sensor transit (its message stamped ``stamp_s``)."""
        self._transit_s = stamp_s

    def _holding_for_transit(self, stamp_s: float) -> bool:
        wait = self.settings.transit_wait_s
        return (
            wait > 0.0
            and math.isfinite(self._transit_s)  # this cell times transits
            and self._transit_s < self._settled_s
            and stamp_s < self._settled_s + wait
        )

    def stop(self) -> None:
        self._settled_s = math.inf

    def reading(
        self,
        stamp_s: float,
        window_s: float,
        speed_mps: float,
        uncertainty_mps: float,
        target_mps: float,
        amplitude_percent: float,
        sensitivity: float = 1.0,
    ) -> float | None:
        """The trimmed amplitude for this reading, or None (not counted, or no step needed).
        ``sensitivity``: ``d ln v / d ln A`` at the set point (NaN or not positive: unknown,
        taken as 1)."""
        cfg = self.settings
        if not (math.isfinite(target_mps) and target_mps != 0.0):
            self.last_note = "no target"
            return None
        if not (math.isfinite(speed_mps) and math.isfinite(uncertainty_mps)):
            self.last_note = "waiting for a valid estimate"
            return None
        if uncertainty_mps > cfg.max_uncertainty * abs(target_mps):
            self.last_note = (
                f"estimate too uncertain to trim on: +-{1e3 * uncertainty_mps:.3g} mm/s > "
                f"{100 * cfg.max_uncertainty:g} % of the target (not calibrated yet?)"
            )
            return None
        if not stamp_s - window_s >= self._settled_s:
            self.last_note = "waiting for an estimate of the current setting"
            return None
        error = (target_mps - speed_mps) / target_mps
        if abs(error) <= max(cfg.deadband, uncertainty_mps / abs(target_mps)):
            self.last_note = f"on target ({100 * error:+.2f} %)"
            return None
        if self._holding_for_transit(stamp_s):
            self.last_note = (
                f"{100 * error:+.2f} % off, holding the setting for a sensor transit to calibrate "
                f"the part model on (at most {cfg.transit_wait_s:g} s)"
            )
            return None
        low, high = SENSITIVITY_RANGE
        known = math.isfinite(sensitivity) and sensitivity > 0.0
        slope = min(max(sensitivity, low), high) if known else 1.0
        # never a step to a negative amplitude (max_step may exceed 1): at most down to zero
        step = max(-min(cfg.max_step, 1.0), min(cfg.max_step, cfg.gain * error / slope))
        self.steps += 1
        self.last_note = f"trimmed the amplitude by {100 * step:+.2f} % ({100 * error:+.2f} % off)"
        self._settled_s = math.inf  # until the caller reports the new setting
        return amplitude_percent * (1.0 + step)
