"""The part calibration on disk: a YAML file the estimator reads at start and rewrites atomically.

The file holds the belief's summary (mean and covariance of ``theta = (ln L, ln D, ln k)``, the
counts) and, for a reader, the values it stands for (friction coefficients, gain, relative
uncertainties). It names the nominal part it was calibrated from: a file made for another part
(another ``mu_s``, ``mu_d``, groove or ``g``) is *foreign* and refused, as is a file that is not
YAML, not this format, of another version, or holds non-finite or non-physical numbers.
:class:`CalibrationFileError` says which and why; the node then runs on the nominal part and
warns.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from feeder_ros.atomic_files import atomic_text
from feeder_ros.estimation.part_belief import PartBelief
from feeder_ros.estimation.stick_slip_observer import PartModel
from feeder_ros.physics.parameters import ParameterError

__all__ = ["FORMAT", "VERSION", "CalibrationFileError", "read_calibration", "write_calibration"]

FORMAT = "feeder_ros/part_calibration"
VERSION = 1
_NOMINAL_KEYS = ("static_friction", "kinetic_friction", "friction_multiplier", "gravity_mps2")


class CalibrationFileError(ValueError):
    """A calibration file that cannot be used; the message names the file and the reason."""


def _nominal_dict(part: PartModel) -> dict[str, float]:
    return {key: float(getattr(part, key)) for key in _NOMINAL_KEYS}


def write_calibration(path: Path | str, belief: PartBelief) -> None:
    """Write ``belief`` to ``path`` (through a temporary file: complete or not at all)."""
    std = belief.std
    cov = belief.covariance
    document: dict[str, Any] = {
        "format": FORMAT,
        "version": VERSION,
        "written": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "nominal_part": _nominal_dict(belief.nominal),
        "theta": {
            "names": ["ln_stick_limit", "ln_slip_deceleration", "ln_accelerometer_gain"],
            "mean": [float(x) for x in belief.mean],
            "estimate": [float(x) for x in belief.estimate],
            "covariance": [[float(x) for x in row] for row in cov],
        },
        "values": {
            "static_friction": belief.static_friction,
            "kinetic_friction": belief.kinetic_friction,
            "accelerometer_gain": belief.gain,
            "relative_uncertainty": {
                "stick_limit": float(std[0]),
                "slip_deceleration": float(std[1]),
                "accelerometer_gain": float(std[2]),
            },
        },
        "transits_used": belief.transits,
        "operator_speeds_used": belief.operator_speeds,
        "operating_points": [[float(f), float(a)] for f, a in belief.points],
    }
    with atomic_text(path, durable=True) as out:
        out.write("# feeder_ros part calibration, written by the vehicle estimator\n")
        yaml.safe_dump(document, out, sort_keys=False)


def read_calibration(path: Path | str, nominal: PartModel) -> PartBelief | None:
    """The belief stored at ``path``; ``None`` if there is no file (nothing calibrated yet).
    Raises :class:`CalibrationFileError` for a file that cannot be used."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return None
    except (OSError, UnicodeDecodeError) as error:
        raise CalibrationFileError(f"{path}: cannot read: {error}") from None
    try:
        document = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise CalibrationFileError(f"{path}: not YAML: {error}") from None
    if not isinstance(document, dict) or document.get("format") != FORMAT:
        found = document.get("format") if isinstance(document, dict) else type(document).__name__
        raise CalibrationFileError(f"{path}: not a {FORMAT} file (format: {found!r})")
    if document.get("version") != VERSION:
        raise CalibrationFileError(
            f"{path}: version {document.get('version')!r}, this build reads version {VERSION}"
        )
    stored = document.get("nominal_part")
    expected = _nominal_dict(nominal)
    if not isinstance(stored, dict) or any(
        not isinstance(stored.get(k), int | float) or not math.isclose(stored[k], v, rel_tol=1e-9)
        for k, v in expected.items()
    ):
        raise CalibrationFileError(
            f"{path}: calibrated for another part ({stored!r}); this estimator's nominal part is "
            f"{expected}"
        )
    try:
        theta = document["theta"]
        mean = np.array(theta["mean"], dtype=np.float64)
        estimate = np.array(theta.get("estimate", theta["mean"]), dtype=np.float64)
        cov = np.array(theta["covariance"], dtype=np.float64)
        points = tuple((float(f), float(a)) for f, a in document.get("operating_points", []))
        belief = PartBelief(
            nominal,
            mean,
            cov,
            estimate=estimate,
            transits=int(document.get("transits_used", 0)),
            operator_speeds=int(document.get("operator_speeds_used", 0)),
            points=points,
        )
    except (KeyError, TypeError, ValueError, ParameterError) as error:
        raise CalibrationFileError(f"{path}: malformed calibration: {error}") from None
    if mean.shape != (3,) or estimate.shape != (3,) or cov.shape != (3, 3):
        raise CalibrationFileError(f"{path}: theta must have 3 values and a 3x3 covariance")
    if not (estimate[1] < estimate[0] and 0.5 <= math.exp(estimate[2]) <= 2.0):
        raise CalibrationFileError(
            f"{path}: non-physical calibration (mu_d >= mu_s, or a gain outside [0.5, 2]): "
            f"theta {estimate.tolist()}"
        )
    return belief
