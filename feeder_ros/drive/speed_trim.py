"""Closed-loop part speed in target-speed mode: trim the amplitude on a trusted estimate (ROS-free).

The speed model gives the set point for a target speed (feed-forward); a real feeder differs from
its model (springs, load, friction), so the speed it reaches is off by as much as the model is.
:class:`SpeedTrim` closes the loop on the sensorless estimate once the estimate can be trusted:

* A reading counts only when it is a valid mean speed (finite, with a finite standard uncertainty
  no larger than ``max_uncertainty`` of the target: an uncalibrated part model's wide interval
  would steer the drive by its own bias) and its window lies wholly after the last set point was
  reached (``window_s`` before its stamp is after the ramp's end): a reading from the previous
  setting says nothing about this one.
* Each counted reading moves the amplitude once, in proportion: ``A *= 1 + gain * e`` with the
  relative error ``e = (target - speed) / target`` (the part speed grows about linearly with the
  amplitude above the slip threshold), the step limited to ``max_step`` relative; no step while
  ``|e|`` lies within the ``deadband`` or within the reading's own relative uncertainty (the loop
  would chase the estimate's noise). The next step waits for a reading of the new setting, so
  the loop cannot run away from a lagging estimate, and the drive's limits and ramps bound every
  step (the caller applies the amplitude through the controller).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from feeder_ros.physics.parameters import ParameterError, is_number

__all__ = ["SpeedTrim", "TrimSettings"]


@dataclass(frozen=True)
class TrimSettings:
    gain: float = 0.6  #: fraction of the relative error corrected per step
    max_step: float = 0.15  #: largest relative amplitude change per step
    deadband: float = 0.005  #: relative errors below this are left alone
    max_uncertainty: float = 0.03  #: readings less sure than this (relative to target) are ignored

    def __post_init__(self) -> None:
        for name in ("gain", "max_step", "max_uncertainty"):
            value = getattr(self, name)
            if not (is_number(value) and math.isfinite(value) and 0.0 < value <= 2.0):
                raise ParameterError(f"speed trim {name}={value!r} must be in (0, 2]")
        if not (is_number(self.deadband) and 0.0 <= self.deadband < 1.0):
            raise ParameterError(f"speed trim deadband={self.deadband!r} must be in [0, 1)")


class SpeedTrim:
    """See the module docstring; the caller supplies times (the node clock)."""

    def __init__(self, settings: TrimSettings | None = None) -> None:
        self.settings = settings if settings is not None else TrimSettings()
        self._settled_s = math.inf
        self.steps = 0
        self.last_note = "no target"

    def setting_changed(self, reached_s: float) -> None:
        """A new set point (a target, a trim step, a restart) is reached at ``reached_s``:
        readings must start after it."""
        self._settled_s = reached_s

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
    ) -> float | None:
        """The trimmed amplitude for this reading, or None (not counted, or no step needed)."""
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
        # never a step to a negative amplitude (max_step may exceed 1): at most down to zero
        step = max(-min(cfg.max_step, 1.0), min(cfg.max_step, cfg.gain * error))
        self.steps += 1
        self.last_note = f"trimmed the amplitude by {100 * step:+.2f} % ({100 * error:+.2f} % off)"
        self._settled_s = math.inf  # until the caller reports the new setting
        return amplitude_percent * (1.0 + step)
