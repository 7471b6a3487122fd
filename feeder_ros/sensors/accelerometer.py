"""A MEMS accelerometer on the carrier: white noise, bias, saturation, seedable.

Axis x is along the track (the carrier's motion), z is up (the sensor measures specific force, so
at rest it reads +g on z). Noise is white with one-sided density ``noise_density`` [m/s^2/sqrt(Hz)]
over the Nyquist band, so each sample has standard deviation ``noise_density*sqrt(rate_hz/2)``.
A real sensor's ``gain`` (scale factor: it reads ``gain`` times the true acceleration) is off by a
few per cent, and it sits tilted on its mount: ``misalignment_deg`` about the cross-track axis
turns the along-track axis towards z, so x reads ``a*cos(d) + g*sin(d)`` (a smaller gain and a
bias) and z reads ``g*cos(d) - a*sin(d)``.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from feeder_ros.physics.parameters import ParameterError

__all__ = ["AccelerometerModel"]


class AccelerometerModel:
    def __init__(
        self,
        rate_hz: float,
        noise_density: float = 0.0,
        bias: float = 0.0,
        saturation: float = math.inf,
        gravity: float = 9.81,
        seed: int = 0,
        gain: float = 1.0,
        misalignment_deg: float = 0.0,
    ) -> None:
        checks = {
            "rate_hz": (rate_hz, rate_hz > 0.0),
            "noise_density": (noise_density, noise_density >= 0.0),
            "bias": (bias, True),
            "saturation": (saturation, saturation > 0.0),
            "gravity": (gravity, True),
            "gain": (gain, gain > 0.0),
            "misalignment_deg": (misalignment_deg, abs(misalignment_deg) <= 45.0),
        }
        for name, (value, ok) in checks.items():
            if math.isnan(value) or not ok or (name != "saturation" and math.isinf(value)):
                raise ParameterError(f"accelerometer {name}={value!r} is out of range")
        self.rate_hz = rate_hz
        self.sigma = noise_density * math.sqrt(rate_hz / 2.0)
        self.bias = bias
        self.saturation = saturation
        self.gravity = gravity
        self.gain = gain
        self.misalignment_rad = math.radians(misalignment_deg)
        self._rng = np.random.default_rng(seed)

    def measure(self, along_track_mps2: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Readings (n, 3) [m/s^2] for true carrier accelerations along the track (n,)."""
        a = np.asarray(along_track_mps2, dtype=np.float64)
        readings = np.zeros((a.size, 3))
        c, s = math.cos(self.misalignment_rad), math.sin(self.misalignment_rad)
        readings[:, 0] = self.gain * (a * c + self.gravity * s) + self.bias
        readings[:, 2] = self.gain * (self.gravity * c - a * s)
        if self.sigma > 0.0:
            readings += self._rng.normal(0.0, self.sigma, readings.shape)
        np.clip(readings, -self.saturation, self.saturation, out=readings)
        return readings
