"""Shared helpers for the physics tests."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from feeder_ros.physics.parameters import FeederParameters


def random_parameters(seed: int, **overrides: object) -> FeederParameters:
    """A plausible random operating point (seeded) around the paper's case study."""
    rng = np.random.default_rng(seed)
    mu_s = float(rng.uniform(0.1, 0.4))
    damping = float(rng.choice([0.0, rng.uniform(1.0, 200.0), rng.uniform(900.0, 5000.0)]))
    values: dict[str, object] = {
        "drive_amplitude_n": float(rng.uniform(5.0, 60.0)),
        "drive_frequency_hz": float(rng.uniform(15.0, 60.0)),
        "damping_ns_per_m": damping,
        "static_friction": mu_s,
        "kinetic_friction": float(mu_s * rng.uniform(0.3, 1.0)),
        "part_mass_kg": float(rng.uniform(0.05, 1.0)),
        "stiffness_switch": str(rng.choice(["displacement", "velocity"])),
        "coupling": str(rng.choice(["one_way", "two_way"])),
    }
    values.update(overrides)
    return FeederParameters().with_changes(**values)


@pytest.fixture
def random_params() -> Callable[..., FeederParameters]:
    """The :func:`random_parameters` factory (conftest modules are not importable by name)."""
    return random_parameters


@pytest.fixture
def case_study() -> FeederParameters:
    """The paper's case study (A = 40 N variant)."""
    return FeederParameters(drive_amplitude_n=40.0)
