"""Plain-language checks of a simulation's inputs and outcome (ROS-free), for ``feeder sim``.

:func:`likely_unit_mistakes` warns before a run about a drive that is probably a unit mistake: a
drive frequency far above both natural frequencies of the carrier (a value in rad/s, or rpm, typed
as Hz: far above resonance the carrier hardly moves), or above half the output sample rate (the
samples alias the vibration). :func:`no_slip_note` says after a run when the parts never slipped
and what would show slip: the carrier's peak acceleration stayed below the stick limit
``L = mu_s*g*kappa`` (Eq. 11), so the parts rode along; the carrier's response scales with the
drive amplitude (the model is linear in A between events), so the amplitude that reaches ``L`` is
about ``A * L / peak``.
"""

from __future__ import annotations

import math

import numpy as np

from feeder_ros.physics.parameters import FeederParameters

__all__ = ["FAR_ABOVE_RESONANCE", "likely_unit_mistakes", "no_slip_note"]

FAR_ABOVE_RESONANCE = 10.0  #: f_d above this many times both natural frequencies: warned
SLIP_MARGIN = 1.5  #: the suggested amplitude takes the peak this far past L


def likely_unit_mistakes(params: FeederParameters, rate_hz: float) -> list[str]:
    """Warnings (empty when the drive looks plausible), each naming the value and a fix."""
    f_d = params.drive_frequency_hz
    warnings = []
    highest = max(params.forward_natural_frequency_hz, params.backward_natural_frequency_hz)
    if f_d > FAR_ABOVE_RESONANCE * highest:
        warnings.append(
            f"drive_frequency_hz={f_d:g} is {f_d / highest:.0f}x the carrier's highest natural "
            f"frequency ({highest:.2f} Hz): far above resonance the carrier hardly moves. The "
            f"drive frequency is in Hz ({f_d:g} rad/s would be {f_d / (2 * math.pi):.4g} Hz)"
        )
    if f_d > rate_hz / 2.0:
        warnings.append(
            f"drive_frequency_hz={f_d:g} is above half the output rate (--rate {rate_hz:g}): "
            f"the samples alias the vibration; use --rate {20 * f_d:g} or more"
        )
    return warnings


def no_slip_note(params: FeederParameters, carrier_a_mps2: np.ndarray) -> str:
    """Why the parts never slipped and how to see slip (call it only when they did not)."""
    limit = params.stick_limit_mps2
    finite = carrier_a_mps2[np.isfinite(carrier_a_mps2)]
    peak = float(np.max(np.abs(finite))) if finite.size else 0.0
    note = (
        f"no part ever slipped: the carrier's peak acceleration {peak:.3g} m/s^2 stayed below "
        f"the stick limit L = mu_s*g*kappa = {limit:.3g} m/s^2, so the parts rode along"
    )
    amplitude = params.drive_amplitude_n
    if peak > 0.0 and amplitude > 0.0:
        needed = float(f"{SLIP_MARGIN * amplitude * limit / peak:.2g}")
        note += (
            f". To see slip, drive harder (about --set drive_amplitude_n={needed:g}: the "
            f"response scales with A) or run --preset realistic"
        )
    else:
        note += ". To see slip, give the drive an amplitude (--set drive_amplitude_n=...)"
    return note
