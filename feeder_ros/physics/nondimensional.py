"""Non-dimensional form of the carrier model (paper Section 3.4, Eqs. 19-20, Fig. 6).

Between switches the sharp carrier model is linear. Scaling branch ``D`` (``f`` forward, ``b``
backward) by its own units

* ``t_cD = sqrt(M_eq / (K_D*cos(theta)))`` (Eq. 20; the paper writes ``M + m``, the code uses the
same
  ``M_eq = M + M_p + alpha*m`` as the dimensional model so that the two agree exactly),
* ``v_cD = A / (K_D*cos(theta))`` (Eq. 20),

turns ``M_eq*v'' + c*v' + K_D*cos(theta)*v = A*sin(omega_d*t)`` into Eq. 19 (plus damping)::

    chi'' + 2*zeta_D*chi' + chi = sin(omega_D*tau),   omega_D = t_cD*omega_d,  zeta_D =
    c*t_cD/(2*M_eq)

with ``v = v_cD*chi`` and ``t = t_cD*tau``. The two branches are joined by the state mapping of Fig.
6 (steps S5 and S9): with ``eta = omega_f/omega_b = t_cb/t_cf`` and ``mu = v_cf/v_cb = K_b/K_f``
(derived from Eq. 20; the paper's printed ``mu = (L_b/L_f)^(3/2)`` is in fact ``eta`` for a constant
flexural rigidity, and ``mu = (L_f/L_b)^3``)::

    forward -> backward:  tau_b = tau_f/eta,  chi_b = mu*chi_f,   chi_b' = mu*eta*chi_f'
    backward -> forward:  tau_f = eta*tau_b,  chi_f = chi_b/mu,   chi_f' = chi_b'/(mu*eta)

:func:`simulate_nondimensional` runs that algorithm for a constant sinusoidal drive, switching on
the sign of the displacement (Eq. 7, the default) or of the velocity (Fig. 6 as printed, with
Filippov holds at ``chi' = 0`` where the drive lies between the two spring forces, in branch units
``chi_b <= sin(omega_d*t) <= chi_f``). Each branch is solved in closed form; switching instants are
found by bracketing and Brent's method on the closed form. The result converts back to SI units, and
the tests check it against the dimensional event-driven engine.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import brentq

from feeder_ros.physics.parameters import FeederParameters

__all__ = [
    "BranchScales",
    "NondimensionalCarrier",
    "NondimensionalScales",
    "simulate_nondimensional",
]

FloatArray = NDArray[np.float64]

FORWARD = 1
BACKWARD = -1


@dataclass(frozen=True)
class BranchScales:
    """Characteristic units of one stiffness branch (Eq. 20) and its coefficients in them."""

    time_s: float  # t_cD
    displacement_m: float  # v_cD
    frequency: float  # omega_D = t_cD*omega_d
    damping_ratio: float  # zeta_D = c*t_cD/(2*M_eq)
    stick_limit: float  # mu_s*g*kappa*t_cD^2/v_cD: Eq. 11 in this branch's units

    @property
    def velocity_mps(self) -> float:
        """Velocity unit v_cD/t_cD."""
        return self.displacement_m / self.time_s

    @property
    def acceleration_mps2(self) -> float:
        """Acceleration unit v_cD/t_cD^2."""
        return self.displacement_m / self.time_s**2


@dataclass(frozen=True)
class NondimensionalScales:
    """Both branches' units and the ratios ``eta`` and ``mu`` that couple them (Fig. 6)."""

    forward: BranchScales
    backward: BranchScales

    @classmethod
    def from_parameters(cls, params: FeederParameters) -> NondimensionalScales:
        amplitude = params.drive_amplitude_n
        if amplitude <= 0.0:
            raise ValueError(
                f"drive_amplitude_n={amplitude!r} N: the non-dimensional form needs A > 0 "
                "(v_c = A/(K*cos(theta)) is its displacement unit)"
            )
        omega_d = 2.0 * math.pi * params.drive_frequency_hz
        mass = params.equivalent_mass_kg

        def branch(stiffness: float) -> BranchScales:
            k_cos = stiffness * params.cos_theta
            t_c = math.sqrt(mass / k_cos)
            v_c = amplitude / k_cos
            return BranchScales(
                time_s=t_c,
                displacement_m=v_c,
                frequency=t_c * omega_d,
                damping_ratio=params.damping_ns_per_m * t_c / (2.0 * mass),
                stick_limit=params.stick_limit_mps2 * t_c**2 / v_c,
            )

        return cls(
            forward=branch(params.forward_stiffness_n_per_m),
            backward=branch(params.backward_stiffness_n_per_m),
        )

    @property
    def eta(self) -> float:
        """omega_f/omega_b = t_cb/t_cf."""
        return self.backward.time_s / self.forward.time_s

    @property
    def mu(self) -> float:
        """v_cf/v_cb = K_b/K_f (= (L_f/L_b)^3 for one plate stack)."""
        return self.forward.displacement_m / self.backward.displacement_m

    def branch(self, branch: int) -> BranchScales:
        return self.forward if branch == FORWARD else self.backward

    def map_state(
        self, branch_from: int, tau: float, chi: float, chi_dot: float
    ) -> tuple[float, float, float]:
        """Map a switching state from ``branch_from``'s units to the other branch's (S5/S9)."""
        eta, mu = self.eta, self.mu
        if branch_from == FORWARD:
            return tau / eta, chi * mu, chi_dot * mu * eta
        return tau * eta, chi / mu, chi_dot / (mu * eta)


class _BranchSolution:
    """Closed-form solution of chi'' + 2*zeta*chi' + chi = sin(w*tau) from (tau0, chi0, chi0')."""

    def __init__(self, scales: BranchScales, tau0: float, chi0: float, chi_dot0: float) -> None:
        zeta, w = scales.damping_ratio, scales.frequency
        if zeta >= 1.0:
            raise ValueError(
                f"damping ratio {zeta:.3g} >= 1 in a branch: the non-dimensional solver covers "
                "underdamped branches only"
            )
        det = (1.0 - w * w) ** 2 + (2.0 * zeta * w) ** 2
        if det == 0.0:
            raise ValueError("undamped drive exactly at a branch's natural frequency (resonance)")
        self.zeta, self.w = zeta, w
        self.p = (1.0 - w * w) / det  # particular solution P*sin(w*tau) + Q*cos(w*tau)
        self.q = -2.0 * zeta * w / det
        self.wd = math.sqrt(1.0 - zeta * zeta)
        self.tau0 = tau0
        # homogeneous part exp(-zeta*s)*(c1*cos(wd*s) + c2*sin(wd*s)), s = tau - tau0
        part0, part_dot0 = self._particular(np.array([tau0]))
        self.c1 = chi0 - float(part0[0])
        self.c2 = (chi_dot0 - float(part_dot0[0]) + zeta * self.c1) / self.wd

    def _particular(self, tau: FloatArray) -> tuple[FloatArray, FloatArray]:
        wt = self.w * tau
        s, c = np.sin(wt), np.cos(wt)
        return self.p * s + self.q * c, self.w * (self.p * c - self.q * s)

    def state(self, tau: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """chi, chi', chi'' at ``tau``."""
        s = tau - self.tau0
        decay = np.exp(-self.zeta * s)
        cs, sn = np.cos(self.wd * s), np.sin(self.wd * s)
        hom = decay * (self.c1 * cs + self.c2 * sn)
        hom_dot = decay * (
            (-self.zeta * self.c1 + self.wd * self.c2) * cs
            + (-self.zeta * self.c2 - self.wd * self.c1) * sn
        )
        part, part_dot = self._particular(tau)
        chi = hom + part
        chi_dot = hom_dot + part_dot
        chi_ddot = np.sin(self.w * tau) - 2.0 * self.zeta * chi_dot - chi
        return chi, chi_dot, chi_ddot

    def chi(self, tau: float) -> float:
        return float(self.state(np.array([tau]))[0][0])


@dataclass(frozen=True)
class NondimensionalCarrier:
    """Carrier samples computed in non-dimensional form, each in its own branch's units."""

    scales: NondimensionalScales
    t_s: FloatArray
    branch: NDArray[np.int8]  # +1 forward (K_f), -1 backward (K_b), 0 held (forward units)
    tau: FloatArray
    chi: FloatArray
    chi_dot: FloatArray
    chi_ddot: FloatArray
    switch_t_s: FloatArray  # switching instants in seconds

    def _unit(self, attribute: str) -> FloatArray:
        forward = float(getattr(self.scales.forward, attribute))
        backward = float(getattr(self.scales.backward, attribute))
        # held samples (branch 0, velocity switching) are stored in forward units
        return np.where(self.branch == BACKWARD, backward, forward).astype(np.float64)

    @property
    def x_m(self) -> FloatArray:
        """Carrier displacement v = v_cD*chi in metres."""
        return self.chi * self._unit("displacement_m")

    @property
    def v_mps(self) -> FloatArray:
        return self.chi_dot * self._unit("velocity_mps")

    @property
    def a_mps2(self) -> FloatArray:
        return self.chi_ddot * self._unit("acceleration_mps2")


def _grid_step(scales: BranchScales) -> float:
    """Bracketing step in branch units: 1/40 of the shorter of the free and the forced period."""
    fastest = max(1.0, scales.frequency)
    return 2.0 * math.pi / fastest / 40.0


def _first_zero(
    func: Callable[[FloatArray], FloatArray], start: float, stop: float, step: float
) -> float:
    """First root of ``func`` after ``start`` (``func > 0`` just after it) up to ``stop``, or inf.

    Brackets on a grid of ``step`` and refines with Brent's method.
    """

    def scalar(x: float) -> float:
        return float(func(np.array([x]))[0])

    left = start
    while left < stop + step:
        grid = left + step * np.arange(1, 257, dtype=np.float64)
        crossing = np.flatnonzero(func(grid) < 0.0)
        if crossing.size:
            j = int(crossing[0])
            a = left if j == 0 else float(grid[j - 1])
            b = float(grid[j])
            if scalar(a) <= 0.0:  # starting on the surface: the value at ``start`` is exactly 0
                a = a + 1e-9 * (b - a)
                if scalar(a) <= 0.0:
                    return a
            return float(brentq(scalar, a, b, xtol=1e-15, rtol=8.9e-16))
        left = float(grid[-1])
    return math.inf


def simulate_nondimensional(
    params: FeederParameters, duration_s: float, output_rate_hz: float
) -> NondimensionalCarrier:
    """Run the Fig. 6 algorithm in non-dimensional form from rest at t = 0 (forward branch first).

    ``stiffness_switch="displacement"`` (Eq. 7): the branches change where ``chi`` changes sign.
    ``"velocity"`` (Fig. 6 as printed): where ``chi'`` changes sign, with Filippov's convention at
    ``chi' = 0`` (as the exact engine): the carrier crosses if both branches push it the same way
    and is held (``v' = 0``, branch code 0) while the drive lies between the two spring forces,
    which in the branches' own units reads ``chi_b <= sin(omega_d*t) <= chi_f``. Samples at
    ``k/output_rate_hz`` s; a sample at a switching instant shows the state just after it.
    """
    if not (duration_s > 0.0 and math.isfinite(duration_s)):
        raise ValueError(f"duration_s={duration_s!r} must be positive and finite")
    if not (output_rate_hz > 0.0 and math.isfinite(output_rate_hz)):
        raise ValueError(f"output_rate_hz={output_rate_hz!r} must be positive and finite")
    on_velocity = params.stiffness_switch == "velocity"
    scales = NondimensionalScales.from_parameters(params)
    omega_d = 2.0 * math.pi * params.drive_frequency_hz
    n_samples = math.floor(duration_s * output_rate_hz + 1e-9) + 1
    t_samples = np.arange(n_samples, dtype=np.float64) / output_rate_hz

    out_branch = np.zeros(n_samples, dtype=np.int8)
    out = np.zeros((4, n_samples))  # tau, chi, chi', chi''
    switches: list[float] = []
    next_sample = 0

    def emit(t_stop: float, final: bool) -> slice:
        """The samples of the current piece (those before ``t_stop``, or all if it is the last)."""
        nonlocal next_sample
        last = n_samples if final else int(np.searchsorted(t_samples, t_stop, side="left"))
        piece = slice(next_sample, max(last, next_sample))
        next_sample = piece.stop
        return piece

    # The state (tau, chi, chi') is kept in the units of branch `units_of` and mapped with Fig. 6's
    # S5/S9 whenever the branch changes. At t = 0 the state sits on the switching surface; the
    # forward branch starts (the third derivative is positive there).
    mode = FORWARD  # +1, -1, or 0: held at v' = 0 (velocity switching)
    units_of = FORWARD
    tau, chi, chi_dot = 0.0, 0.0, 0.0
    while next_sample < n_samples:
        units = scales.branch(units_of)
        if mode == 0:
            t0 = tau * units.time_s
            chi_f = chi if units_of == FORWARD else chi / scales.mu
            chi_b = chi_f * scales.mu
            step_s = 2.0 * math.pi / omega_d / 80.0

            def room_forward(t: FloatArray, c: float = chi_f) -> FloatArray:
                return np.asarray(c - np.sin(omega_d * t))

            def room_backward(t: FloatArray, c: float = chi_b) -> FloatArray:
                return np.asarray(np.sin(omega_d * t) - c)

            release_f = _first_zero(room_forward, t0, duration_s, step_s)
            release_b = _first_zero(room_backward, t0, duration_s, step_s)
            t_end = min(release_f, release_b)
            piece = emit(t_end, t_end >= duration_s)
            out[0, piece] = t_samples[piece] / scales.forward.time_s  # held: forward units
            out[1, piece] = chi_f
            out[2:, piece] = 0.0
            out_branch[piece] = 0
            if t_end >= duration_s:
                break
            switches.append(t_end)
            mode = FORWARD if release_f <= release_b else BACKWARD
            tau = t_end / units.time_s
            if mode != units_of:
                tau, chi, chi_dot = scales.map_state(units_of, tau, chi, 0.0)
                units_of = mode
            continue

        solution = _BranchSolution(units, tau, chi, chi_dot)

        def side(taus: FloatArray, sol: _BranchSolution = solution, b: int = mode) -> FloatArray:
            return b * sol.state(taus)[1 if on_velocity else 0]

        tau_switch = _first_zero(side, tau, duration_s / units.time_s, _grid_step(units))
        t_end = tau_switch * units.time_s
        piece = emit(t_end, t_end >= duration_s)
        taus = t_samples[piece] / units.time_s
        out[0, piece] = taus
        out[1:, piece] = np.vstack(solution.state(taus))
        out_branch[piece] = mode
        if t_end >= duration_s:
            break
        switches.append(t_end)
        chi_sw, chi_dot_sw, _ = (float(q[0]) for q in solution.state(np.array([tau_switch])))
        if on_velocity:
            chi, chi_dot = chi_sw, 0.0
            new_mode = _classify_at_rest(scales, omega_d * t_end, chi, units_of, mode)
        else:
            chi, chi_dot = 0.0, chi_dot_sw
            new_mode = -mode
        tau = tau_switch
        if new_mode != 0 and new_mode != units_of:
            tau, chi, chi_dot = scales.map_state(units_of, tau, chi, chi_dot)
            units_of = new_mode
        mode = new_mode

    return NondimensionalCarrier(
        scales=scales,
        t_s=t_samples,
        branch=out_branch,
        tau=out[0],
        chi=out[1],
        chi_dot=out[2],
        chi_ddot=out[3],
        switch_t_s=np.array(switches),
    )


def _classify_at_rest(
    scales: NondimensionalScales, phase: float, chi: float, units_of: int, previous: int
) -> int:
    """Branch after reaching v' = 0 at ``chi`` (in ``units_of``'s units), velocity switching.

    Filippov: in each branch's own units the acceleration at rest is ``sin(omega_d*t) - chi_D``.
    """
    chi_f = chi if units_of == FORWARD else chi / scales.mu
    chi_b = chi_f * scales.mu
    drive = math.sin(phase)
    a_f = drive - chi_f
    a_b = drive - chi_b
    if a_f > 0.0 and a_b > 0.0:
        return FORWARD
    if a_f < 0.0 and a_b < 0.0:
        return BACKWARD
    if a_f <= 0.0 <= a_b:
        return 0  # both branches push back onto v' = 0: held
    return previous  # both push away (repelling surface): keep going the way it came
