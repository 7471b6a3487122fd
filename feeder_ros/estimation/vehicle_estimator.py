"""Sensorless stick-slip vehicle estimator: a part's motion from the carrier's acceleration alone.

(About 870 lines, one class: the pipeline's stages below share its sample buffers and drive epoch;
its records and settings are in :mod:`~feeder_ros.estimation.estimator_records`.)

Pipeline (ROS-free, no clock; :meth:`VehicleEstimator.push` takes batches of accelerometer samples):

1. **Input checks.** Non-finite samples, and samples beyond ``MAX_ABS_SAMPLE`` (1e6 m/s^2 or m: no
   sensor reads that; the fit's arithmetic would overflow), are dropped (``INVALID_SAMPLES``,
   counted over the window, whatever the batching of the input); samples not after the last accepted
   stamp are dropped (``OUT_OF_ORDER``); a jump back by more than ``clock_reset_s`` (a replayed bag,
   a restarted clock) resets the estimator. An interval longer than ``gap_factor`` times the nominal
   sample period is a gap (``GAP``): up to ``max_bridge_s`` it is bridged by the periodic carrier
   model (the part is propagated through it, but the bridged time never enters the window
   statistics); a longer gap restarts the part observer and the statistics.
2. **Carrier model** (:mod:`~feeder_ros.estimation.carrier_velocity`): a harmonic fit of the last
   ``fit_window_s`` of acceleration at the response period ``n/f_d`` (``n`` by BIC), refitted every
   ``refit_interval_s``, harmonics below ``coefficient_threshold_sigma`` dropped; velocity by
   term-wise integration, free of drift and bias. ``f_d`` is the drive command
   (:meth:`~VehicleEstimator.set_drive`) or, without one, estimated from the spectrum and refined
   on the harmonic model.
3. **Part** (:mod:`~feeder_ros.estimation.stick_slip_observer`): the Coulomb stick-slip model of the
   nominal part, driven by the modelled carrier velocity and acceleration, event-accurate.
4. **Window statistics**: mean speed and slip fraction over the last ``window_s`` (measured time
   only), net advance over the last drive cycle.

Confidences (all in [0, 1]) multiply: the carrier model's smooth model error against
``model_error_scale * mu_s*g*kappa`` (transient, chaos, wrong period), the fill of the fit window,
the settling of the part state, the measured fraction of the statistics window and, for mean speed,
advance and slip fraction, their sensitivity to the modelled acceleration's uncertainty (a peak that
grazes the stick limit makes them fragile). The phase confidence adds the margin of the current
phase (distance to the stick limit, or relative velocity) in units of its uncertainty.

A drive change (commanded, or detected because new samples contradict a good carrier model)
restarts the carrier fit and the statistics at the change (``DRIVE_CHANGED`` while the change lies
inside the window). Samples wait until a carrier model exists, so the first records after start or
a change are ``SETTLING`` and carry no estimate (``nan``, confidence 0).

Status priority when several conditions hold inside the window: OUT_OF_ORDER, INVALID_SAMPLES, GAP,
DRIVE_CHANGED, SETTLING; ``status_message`` names all of them (and a poor carrier model).
"""

from __future__ import annotations

import collections
import contextlib
import math
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from feeder_ros.estimation.carrier_velocity import (
    CarrierFitError,
    HarmonicFit,
    estimate_frequency,
    fit_harmonics,
    harmonic_count,
    refine_frequency,
    select_period_order,
)
from feeder_ros.estimation.estimator_records import (
    Columns,
    EstimateTrace,
    EstimatorConfig,
    Status,
    VehicleEstimate,
    WindowStatistics,
    confidence,
    empty_trace,
)
from feeder_ros.estimation.part_belief import CarrierRun, PartBelief, predict_speed
from feeder_ros.estimation.stick_slip_observer import (
    PHASE_STICK,
    PartModel,
    StickSlipObserver,
)
from feeder_ros.physics.parameters import ParameterError

__all__ = [
    "EstimateTrace",
    "EstimatorConfig",
    "Status",
    "VehicleEstimate",
    "VehicleEstimator",
    "load_kernels",
]

F64 = npt.NDArray[np.float64]
B = npt.NDArray[np.bool_]

_HIST_SUMS = ("x_all", "x_valid", "slip_valid", "time_valid")
#: the uncertainty runs (the part on the fit, once per belief particle) are redone this often
UNCERTAINTY_INTERVAL_S = 0.5
#: a sample's largest magnitude (m/s^2, or m for displacement input): beyond it the sample is
#: invalid, as a non-finite one is (no accelerometer reads 100,000 g; the fit would overflow)
MAX_ABS_SAMPLE = 1e6


_PRIORITY = (
    Status.OUT_OF_ORDER,
    Status.INVALID_SAMPLES,
    Status.GAP,
    Status.SETTLING,
    Status.DRIVE_CHANGED,
)


def _smoothed(old: float, new: float, fresh: bool) -> float:
    if fresh or not (math.isfinite(old) and math.isfinite(new)):
        return new
    return old + 0.3 * (new - old)


class VehicleEstimator:
    """Stateful sensorless estimator (see the module docstring). Not thread-safe.

    ``VehicleEstimator(config=EstimatorConfig())``. Feed :meth:`push` with accelerometer batches
    (stamps in seconds, any epoch), optionally :meth:`set_drive` with the drive command; each call
    returns the latest :class:`VehicleEstimate`; :attr:`last_trace` holds the per-sample estimates
    of that call.
    """

    def __init__(
        self, config: EstimatorConfig | None = None, belief: PartBelief | None = None
    ) -> None:
        self._cfg = config if config is not None else EstimatorConfig()
        cfg = self._cfg
        self._belief = (
            belief
            if belief is not None
            else PartBelief.prior(cfg.part, cfg.friction_uncertainty, cfg.gain_uncertainty)
        )
        self._observer = StickSlipObserver(self._belief.measured_part())
        self._command: tuple[float, float] | None = None
        self.reset()

    # -- public state ------------------------------------------------------------------------
    @property
    def config(self) -> EstimatorConfig:
        return self._cfg

    @property
    def fit(self) -> HarmonicFit | None:
        """The current carrier model (``None`` before the first fit or right after a drive
        change)."""
        return self._fit

    @property
    def drive_frequency_hz(self) -> float:
        return self._freq if self._freq is not None else math.nan

    @property
    def last_trace(self) -> EstimateTrace:
        return self._trace

    @property
    def last_estimate(self) -> VehicleEstimate:
        return self._record

    @property
    def belief(self) -> PartBelief:
        """The part model in use, with its uncertainty."""
        return self._belief

    @property
    def drive_command(self) -> tuple[float, float] | None:
        """The last drive command (frequency Hz, amplitude), or None."""
        return self._command

    @property
    def steady_since_s(self) -> float:
        """Since when the carrier has run steadily at the current drive setting and the estimate
        rests on a converged carrier model (nan while settling): measurements of the part's speed
        that lie wholly after it belong to this operating point."""
        return self._valid_from

    def set_belief(self, belief: PartBelief) -> None:
        """Use another part model (a calibration's): from now on, with its uncertainty. The
        statistics window runs on; its older part carries the old model for up to ``window_s``,
        and the reported uncertainty moves to the new one over about a second."""
        self._belief = belief
        self._observer.set_part(belief.measured_part())
        self._sensitivity_fresh = True
        self._last_fit_t = -math.inf  # refit (and re-derive the uncertainty) at the next samples

    def reset(self) -> None:
        """Forget all samples and estimates (the drive command is kept)."""
        self._observer.reset()
        self._fitbuf = Columns(("t", "a"), (np.float64, np.float64))
        self._pending = Columns(("t", "a", "m"), (np.float64, np.float64, np.bool_))
        self._hist = Columns(
            ("t", "x_all", "x_valid", "slip_valid", "time_valid"),
            (np.float64, np.float64, np.float64, np.float64, np.float64),
        )
        self._last_t = -math.inf
        self._prev_measured = False
        self._dt_nominal: float | None = None
        self._fit: HarmonicFit | None = None
        self._q_slip = 1.0
        self._sigma_carrier = self._sigma_part = self._spread = math.nan
        self._last_uncertainty_t = -math.inf
        self._converged_t = math.nan  # first converged carrier fit of this drive epoch
        self._valid_from = math.nan  # the statistics count from here (converged, part settled)
        self._sensitivity_fresh = True
        self._last_carrier = (math.nan, math.nan)
        self._order = 1
        self._last_fit_t = -math.inf
        self._last_order_t = -math.inf
        self._t_ref: float | None = None
        self._epoch_start = math.nan  # start of the current drive epoch (fit data from here)
        self._stats_start = math.nan
        self._observer_start = math.nan
        self._events: dict[Status, float] = {}
        self._event_notes: dict[Status, str] = {}
        # (stamp, count) of the invalid samples dropped per processed batch: reported summed
        # over the window, so the report does not depend on how the input was batched
        self._invalid: collections.deque[tuple[float, int]] = collections.deque()
        self._freq: float | None = self._command[0] if self._command is not None else None
        self._freq_refined = False
        self._scheduled: tuple[float, float] | None = None
        self._quantity: str | None = None
        self._stage_t: list[F64] = []
        self._stage_a: list[F64] = []
        self._stage_start = math.nan
        self._trace = empty_trace()
        self._record = self._make_record()

    # -- inputs ------------------------------------------------------------------------------
    def set_drive(self, frequency_hz: float, amplitude: float, t_s: float) -> None:
        """The drive command: frequency [Hz] and amplitude (any unit) from time ``t_s`` on.

        A change of either restarts the carrier fit and the statistics at ``t_s`` (or at the last
        sample if the command arrives late)."""
        f = float(frequency_hz)
        amp = float(amplitude)
        if not (math.isfinite(f) and f > 0.0):
            raise ParameterError(f"frequency_hz={frequency_hz!r} must be finite and > 0")
        if not math.isfinite(amp) or not math.isfinite(float(t_s)):
            raise ParameterError(f"amplitude={amplitude!r} and t_s={t_s!r} must be finite")
        previous = self._command
        if previous == (f, amp):
            return  # a repeated command (a drive re-sends its set point) changes nothing
        self.flush()  # staged samples belong to the drive before this command
        self._command = (f, amp)
        close = self._freq is not None and abs(self._freq - f) <= self._cfg.frequency_tolerance * f
        if previous is None and close:
            # the first command confirms the estimate: adopt its exact value, no restart
            self._freq = f
            self._last_fit_t = self._last_order_t = -math.inf
            return
        if math.isfinite(self._last_t) and float(t_s) > self._last_t:
            self._scheduled = (float(t_s), f)  # applied when the samples reach t_s
        else:
            self._scheduled = None
            self._drive_change(float(t_s), f, "drive command")

    def push(self, t_s: npt.ArrayLike, accel_mps2: npt.ArrayLike) -> VehicleEstimate:
        """Add accelerometer samples (carrier acceleration along the track, m/s^2) and estimate.

        Pushes spanning less than ``batch_interval_s`` are staged and processed together once the
        staged stamps span it (the returned record is then up to that much old); :meth:`flush`
        processes them at once."""
        return self._push(t_s, accel_mps2, "acceleration")

    def push_carrier_state(
        self, t_s: npt.ArrayLike, displacement_m: npt.ArrayLike
    ) -> VehicleEstimate:
        """Add carrier displacement samples (a displacement sensor, m, any zero) and estimate.

        The same pipeline runs on the displacement: its harmonic fit is differentiated term by term
        (harmonics up to ``displacement_max_harmonic_hz``: differentiating amplifies sensor noise by
        ``(k w)^2``). One estimator takes one kind of input; reset() to switch.
        """
        return self._push(t_s, displacement_m, "displacement")

    def flush(self) -> VehicleEstimate:
        """Process the samples staged by small pushes now (see ``batch_interval_s``)."""
        if not self._stage_t:
            return self._record
        t = np.concatenate(self._stage_t)
        a = np.concatenate(self._stage_a)
        self._stage_t, self._stage_a = [], []
        return self._process(t, a)

    def _push(self, t_s: npt.ArrayLike, values: npt.ArrayLike, quantity: str) -> VehicleEstimate:
        if self._quantity is None:
            self._quantity = quantity
        elif self._quantity != quantity:
            raise ValueError(
                f"this estimator is fed {self._quantity} samples; reset() before feeding {quantity}"
            )
        t = np.asarray(t_s, dtype=np.float64).ravel()
        a = np.asarray(values, dtype=np.float64).ravel()
        if t.shape != a.shape:
            raise ValueError(f"{t.size} stamps but {a.size} values")
        if t.size == 0:
            return self._record
        # small pushes (one IMU message each) are staged and processed together: the per-call
        # cost, not the per-sample cost, dominates at 1 kHz
        self._stage_t.append(t)
        self._stage_a.append(a)
        stamp = float(t[-1])
        if not math.isfinite(self._stage_start):
            self._stage_start = float(t[0])
        if (
            self._cfg.batch_interval_s <= 0.0
            or not math.isfinite(stamp)
            or not math.isfinite(self._stage_start)
            or abs(stamp - self._stage_start) >= self._cfg.batch_interval_s
        ):
            self._stage_start = math.nan
            return self.flush()
        self._trace = empty_trace()
        return self._record

    def _process(self, t: F64, a: F64) -> VehicleEstimate:
        self._trace = empty_trace()
        if t.size == 0:
            return self._record
        finite = np.isfinite(t) & (np.abs(a) <= MAX_ABS_SAMPLE)  # False for nan too
        if not np.all(finite):
            bad = int(np.count_nonzero(~finite))
            stamps = t[np.isfinite(t)]
            when = float(stamps.max()) if stamps.size else self._last_t
            self._invalid.append((when if math.isfinite(when) else -math.inf, bad))
            self._note(Status.INVALID_SAMPLES, when, "")  # message: see _conditions
            t, a = t[finite], a[finite]
        if t.size and t[-1] < self._last_t - self._cfg.clock_reset_s:
            jump = self._last_t - float(t[-1])
            self.reset()
            self._note(Status.OUT_OF_ORDER, float(t[-1]), f"clock jumped back {jump:.3g} s: reset")
        if t.size:
            running = np.maximum.accumulate(np.concatenate(([self._last_t], t)))[:-1]
            keep = t > running
            if not np.all(keep):
                dropped = int(np.count_nonzero(~keep))
                self._note(
                    Status.OUT_OF_ORDER,
                    float(running[-1] if keep[-1] else max(running[-1], t[-1])),
                    f"{dropped} samples with stamps not after the last one dropped",
                )
                t, a = t[keep], a[keep]
        scheduled = self._scheduled
        if t.size and scheduled is not None and t[-1] >= scheduled[0]:
            k = int(np.searchsorted(t, scheduled[0], side="left"))
            if k:
                self._accept(t[:k], a[:k])
            self._scheduled = None
            self._drive_change(scheduled[0], scheduled[1], "drive command")
            t, a = t[k:], a[k:]
        if t.size:
            self._accept(t, a)
        self._estimate_pending()
        self._record = self._make_record()
        return self._record

    # -- internals ---------------------------------------------------------------------------
    def _note(self, status: Status, t: float, message: str) -> None:
        self._events[status] = t if math.isfinite(t) else -math.inf
        self._event_notes[status] = message

    def _accept(self, t: F64, a: F64) -> None:
        cfg = self._cfg
        prev = self._last_t
        times = np.concatenate(([prev], t)) if math.isfinite(prev) else t
        steps = np.diff(times)
        if self._dt_nominal is None and steps.size >= 3:
            self._dt_nominal = float(np.median(steps))
        synth_t: list[F64] = []
        if self._dt_nominal is not None and steps.size:
            gaps = np.flatnonzero(steps > cfg.gap_factor * self._dt_nominal)
            for g in gaps:
                t0, t1 = float(times[g]), float(times[g + 1])
                self._note(Status.GAP, t1, f"gap of {t1 - t0:.4g} s at t={t0:.6f}")
                if t1 - t0 > cfg.max_bridge_s or self._fit is None:
                    # too long to bridge: the part restarts after it, statistics restart
                    self._flush_before(t1)
                    self._observer.reset()
                    self._observer_start = t1
                    self._stats_start = t1
                    if math.isfinite(self._valid_from):
                        self._valid_from = t1 + cfg.observer_settle_s
                        self._stats_start = self._valid_from
                else:
                    n = max(1, round((t1 - t0) / self._dt_nominal))
                    synth_t.append(t0 + (t1 - t0) * np.arange(1, n) / n)
            # track the nominal period slowly (robust to the gaps just found)
            normal = steps[steps <= cfg.gap_factor * self._dt_nominal]
            if normal.size:
                self._dt_nominal += 0.05 * (float(np.median(normal)) - self._dt_nominal)
        if math.isnan(self._epoch_start):
            self._epoch_start = float(t[0])
            self._stats_start = float(t[0])
            self._observer_start = float(t[0])
        if self._t_ref is None:
            self._t_ref = float(t[0])
        self._last_t = float(t[-1])
        self._fitbuf.append(t=t, a=a)
        self._fitbuf.drop_before(self._last_t - 2.0 * cfg.fit_window_s)
        if synth_t:
            st = np.concatenate(synth_t)
            all_t = np.concatenate((t, st))
            order = np.argsort(all_t, kind="stable")
            m = np.concatenate((np.ones(t.size, bool), np.zeros(st.size, bool)))[order]
            av = np.concatenate((a, np.full(st.size, np.nan)))[order]
            self._pending.append(t=all_t[order], a=av, m=m)
        else:
            self._pending.append(t=t, a=a, m=np.ones(t.size, bool))
        self._maybe_track_frequency()
        self._maybe_refit()

    def _flush_before(self, t1: float) -> None:
        """Estimate the pending samples before ``t1`` with the current model (or drop them)."""
        if len(self._pending) == 0:
            return
        pt = self._pending.col("t")
        k = int(np.searchsorted(pt, t1, side="left"))
        if k == 0:
            return
        if self._fit is not None:
            self._run_observer(
                pt[:k].copy(), np.asarray(self._pending.col("m")[:k], dtype=bool).copy()
            )
        self._pending.drop_before(t1)

    def _drive_change(self, t_c: float, frequency_hz: float | None, why: str) -> None:
        if math.isfinite(self._last_t):
            t_c = max(t_c, self._epoch_start)
            self._flush_before(t_c)
            what = f"{frequency_hz:.6g} Hz" if frequency_hz is not None else "frequency unknown"
            self._note(Status.DRIVE_CHANGED, t_c, f"{why} ({what}) at t={t_c:.6f}")
            self._stats_start = t_c
            self._epoch_start = t_c
            self._fitbuf.drop_before(t_c)
        self._freq = frequency_hz
        self._freq_refined = False
        self._sensitivity_fresh = True
        self._converged_t = self._valid_from = math.nan
        self._fit = None
        self._order = 1
        self._last_fit_t = -math.inf
        self._last_order_t = -math.inf

    def _maybe_track_frequency(self) -> None:
        """Without a drive command: a first (coarse) frequency once ``min_fit_s`` of data exist."""
        cfg = self._cfg
        if self._command is not None or self._freq is not None:
            return
        t = self._fitbuf.col("t")
        if len(t) < 16 or float(t[-1] - t[0]) < cfg.min_fit_s:
            return
        lo, hi = cfg.frequency_band_hz
        try:
            self._freq = estimate_frequency(
                np.asarray(t, dtype=np.float64),
                np.asarray(self._fitbuf.col("a"), dtype=np.float64),
                lo,
                hi,
            )
        except CarrierFitError:
            return
        self._freq_refined = False

    def _model_broken(self) -> bool:
        """True when the newest samples (not yet fitted) contradict a good carrier model: the drive
        (or the plant) changed. A poor model (transient, chaos) is never declared broken."""
        fit = self._fit
        cfg = self._cfg
        if fit is None:
            return False
        scale = cfg.model_error_scale * cfg.part.stick_limit_mps2
        if fit.model_error_rms_mps2 > scale:
            return False
        t_all = self._fitbuf.col("t")
        k = int(np.searchsorted(t_all, fit.t_end_s, side="right"))
        if len(t_all) - k < 10:
            return False
        t = np.asarray(t_all[k:], dtype=np.float64)
        y = np.asarray(self._fitbuf.col("a")[k:], dtype=np.float64)
        err = y - fit.measurement(t)
        err = err * fit.to_acceleration
        rms = math.sqrt(float(np.dot(err, err)) / err.size)
        return rms > 3.0 * fit.residual_rms_mps2 + 2.0 * scale

    def _search_frequency(self, t: F64, a: F64) -> None:
        """Before an order check without a command: while the model is poor (first fit, transient,
        a wrong frequency) search afresh (spectrum, then +-2 %); a good model only needs a nudge."""
        cfg = self._cfg
        fit = self._fit
        poor = (
            fit is None
            or not self._freq_refined
            or fit.model_error_rms_mps2 > cfg.model_error_scale * cfg.part.stick_limit_mps2
        )
        if poor:
            lo, hi = cfg.frequency_band_hz
            with contextlib.suppress(CarrierFitError):
                self._freq = estimate_frequency(t, a, lo, hi)
            self._refine_frequency(t, a, 1, 0.02)
        else:
            self._refine_frequency(t, a, 1, 0.003)

    def _refine_frequency(self, t: F64, a: F64, order: int, relative_range: float) -> None:
        assert self._freq is not None
        self._freq = refine_frequency(
            t, a, self._freq, order, self._max_harmonic_hz, relative_range, self._t_ref or 0.0
        )

    @property
    def _max_harmonic_hz(self) -> float:
        if self._quantity == "displacement":
            return self._cfg.displacement_max_harmonic_hz
        return self._cfg.max_harmonic_hz

    def _maybe_refit(self) -> None:
        cfg = self._cfg
        if self._fit is not None and self._last_t - self._last_fit_t < cfg.refit_interval_s:
            return  # not due (the change check below runs at the refit rate too)
        if self._fit is not None and self._model_broken():
            assert self._fit is not None
            t_c = self._fit.t_end_s
            freq = self._command[0] if self._command is not None else None
            self._drive_change(t_c, freq, "carrier motion changed")
        if self._freq is None or self._dt_nominal is None or self._t_ref is None:
            return
        t_all = self._fitbuf.col("t")
        if len(t_all) < 8 or float(t_all[-1] - t_all[0]) < cfg.min_fit_s:
            return
        if self._fit is not None and self._last_t - self._last_fit_t < cfg.refit_interval_s:
            return
        # the newest fit_window_s worth of *samples*: across a gap the window reaches further back
        # (the model is periodic), and a handful of fresh samples never make a fit on their own
        count = round(cfg.fit_window_s / self._dt_nominal)
        k = max(0, len(t_all) - count)
        if len(t_all) - k < cfg.min_fit_s / self._dt_nominal:
            return
        t = np.asarray(t_all[k:], dtype=np.float64)
        a = np.asarray(self._fitbuf.col("a")[k:], dtype=np.float64)
        try:
            since = self._last_t - self._last_order_t
            poor = self._fit is not None and self._fit.model_error_rms_mps2 > (
                cfg.model_error_scale * cfg.part.stick_limit_mps2
            )
            interval = cfg.order_check_interval_s * (0.25 if poor else 1.0)
            if self._fit is None or since >= interval:
                if self._command is None:
                    self._search_frequency(t, a)
                self._order, fit = select_period_order(
                    t, a, self._freq, cfg.max_period_order, self._max_harmonic_hz, self._t_ref,
                    self._quantity or "acceleration",
                )  # fmt: skip
                if self._command is None:
                    self._refine_frequency(t, a, self._order, 0.001)
                    fit = fit_harmonics(
                        t, a, self._freq / self._order, fit.harmonic_count, self._t_ref,
                        self._quantity or "acceleration",
                    )  # fmt: skip
                    self._freq_refined = True
                self._last_order_t = self._last_t
            else:
                base = self._freq / self._order
                rate = 1.0 / self._dt_nominal
                K = min(harmonic_count(base, rate, self._max_harmonic_hz), (t.size - 3) // 2 - 1)
                fit = fit_harmonics(t, a, base, K, self._t_ref, self._quantity or "acceleration")
        except CarrierFitError:
            return
        self._fit = fit.significant(cfg.coefficient_threshold_sigma)
        self._note_convergence(self._fit)
        self._last_fit_t = self._last_t
        fresh = self._sensitivity_fresh
        if not fresh and self._last_t - self._last_uncertainty_t < UNCERTAINTY_INTERVAL_S:
            return  # the uncertainty runs (one per belief particle) are not due
        sigma_carrier, sigma_part, spread, q_slip = self._uncertainty(self._fit)
        # one fit is a noisy snapshot: smoothed over a few updates (about 1.5 s), except the
        # first fit of an epoch or a new belief (no history) and a value that is not finite
        self._sigma_carrier = _smoothed(self._sigma_carrier, sigma_carrier, fresh)
        self._sigma_part = _smoothed(self._sigma_part, sigma_part, fresh)
        self._spread = _smoothed(self._spread, spread, fresh)
        self._q_slip = _smoothed(self._q_slip, q_slip, fresh)
        self._sensitivity_fresh = False
        self._last_uncertainty_t = self._last_t

    def _note_convergence(self, fit: HarmonicFit) -> None:
        """The first fit of a drive epoch that covers a full fit window with a small model error
        (the carrier's transient has decayed, the period order is right) converges the carrier
        model; the statistics count from ``observer_settle_s`` after it."""
        cfg = self._cfg
        if math.isfinite(self._converged_t):
            return
        full = fit.span_s >= 0.9 * cfg.fit_window_s
        small = fit.model_error_rms_mps2 <= cfg.model_error_scale * cfg.part.stick_limit_mps2
        if full and small:
            self._converged_t = self._last_t
            self._valid_from = self._last_t + cfg.observer_settle_s
            self._stats_start = max(self._stats_start, self._valid_from)

    def _uncertainty(self, fit: HarmonicFit) -> tuple[float, float, float, float]:
        """Standard uncertainties of the mean speed [true m/s] from the carrier model and from the
        part model, the part model's share of the part velocity's uncertainty, and the slip
        fraction's confidence factor, from runs of the part on the fit (one fit window, the
        first half to settle; ``docs/model.md`` section 12.3):

        * carrier: the stick limit moved by +-1 sigma of the modelled acceleration (noise and
          model error; equivalently the carrier's acceleration shifted against a fixed limit):
          where a peak grazes the limit the speed swings, and the larger swing is the sigma;
        * part model: ``sqrt(J Sigma J^T)`` of the belief (friction, gain) by central
          differences over each parameter's standard deviation.

        A 1-sigma swing of 0.02 of the slip fraction halves its confidence factor."""
        belief = self._belief
        dt = self._dt_nominal or 1e-3
        run = CarrierRun.over(fit, dt, max(self._cfg.fit_window_s, 4.0 / fit.base_frequency_hz))
        k = belief.gain
        part = belief.measured_part()
        delta = fit.acceleration_uncertainty_mps2
        speeds, slips = [], []
        for shift in (-delta, 0.0, delta):
            limit = part.stick_limit_mps2 + shift
            if limit <= part.slip_deceleration_mps2:
                return math.inf, math.inf, math.inf, 0.0
            obs = StickSlipObserver(PartModel(limit / part.gravity_mps2, part.kinetic_friction))
            out = obs.update(run.t_s, run.velocity_mps, run.acceleration_mps2)
            T = float(run.t_s[-1] - run.t_s[run.settle])
            speeds.append(float(np.sum(out.part_dx_m[run.settle + 1 :])) / T / k)
            slips.append(float(np.sum(out.slip_s[run.settle + 1 :])) / T)
        sigma_carrier = max(abs(speeds[0] - speeds[1]), abs(speeds[2] - speeds[1]))
        d_slip = max(abs(slips[0] - slips[1]), abs(slips[2] - slips[1]))
        prediction = predict_speed(run, belief)
        return (
            sigma_carrier,
            prediction.uncertainty_mps,
            prediction.velocity_spread_mps,
            1.0 / (1.0 + (d_slip / 0.02) ** 2),
        )

    def _estimate_pending(self) -> None:
        if self._fit is None or len(self._pending) == 0:
            return
        t = np.asarray(self._pending.col("t"), dtype=np.float64).copy()
        m = np.asarray(self._pending.col("m"), dtype=bool).copy()
        self._pending.clear()
        self._run_observer(t, m)

    def _run_observer(self, t: F64, measured: B) -> None:
        fit = self._fit
        assert fit is not None
        obs = self._observer
        if obs.started:
            # the interval from the last processed sample uses the current model at both ends
            _, v, a = fit.evaluate(np.concatenate(([obs.time_s], t)))
            obs.restart_interval(float(v[0]), float(a[0]))
            v, a = v[1:], a[1:]
        else:
            _, v, a = fit.evaluate(t)
            self._observer_start = float(t[0])
        self._last_carrier = (float(v[-1]), float(a[-1]))
        out = obs.update(t, v, a)
        # interval k ends at sample k; it is measured if both ends are
        prev_m = self._prev_measured if len(self._hist) else False
        both = measured & np.concatenate(([prev_m], measured[:-1]))
        prev_t = float(self._hist.col("t")[-1]) if len(self._hist) else float(t[0])
        dt = np.diff(np.concatenate(([prev_t], t)))
        if len(self._hist):
            x_all0, xv0, sv0, tv0 = (float(self._hist.col(n)[-1]) for n in _HIST_SUMS)
        else:
            x_all0 = xv0 = sv0 = tv0 = 0.0
        # samples at or before the statistics start contribute nothing
        after = t > self._stats_start
        valid = both & after
        self._hist.append(
            t=t,
            x_all=x_all0 + np.cumsum(out.part_dx_m),
            x_valid=xv0 + np.cumsum(np.where(valid, out.part_dx_m, 0.0)),
            slip_valid=sv0 + np.cumsum(np.where(valid, out.slip_s, 0.0)),
            time_valid=tv0 + np.cumsum(np.where(valid, dt, 0.0)),
        )
        self._prev_measured = bool(measured[-1])
        keep_s = max(self._cfg.window_s, 2.0 / (self._freq or 1.0)) + 1.0
        self._hist.drop_before(float(t[-1]) - keep_s, keep_one=True)
        tr = self._trace
        self._trace = EstimateTrace(
            np.concatenate((tr.t_s, t)),
            np.concatenate((tr.carrier_v_mps, v)),
            np.concatenate((tr.carrier_a_mps2, a)),
            np.concatenate((tr.part_v_mps, out.part_v_mps)),
            np.concatenate((tr.phase, out.phase)),
            np.concatenate((tr.measured, measured)),
        )

    def _cumulative_at(self, name: str, t_q: float) -> float:
        t = self._hist.col("t")
        y = self._hist.col(name)
        return float(np.interp(t_q, t, y))

    def _make_record(self) -> VehicleEstimate:
        cfg = self._cfg
        nan = math.nan
        conditions = self._conditions()
        status = next((s for s in _PRIORITY if s in conditions), Status.OK)
        notes = list(conditions.values())
        fit = self._fit
        scale = cfg.model_error_scale * cfg.part.stick_limit_mps2
        if fit is not None and fit.model_error_rms_mps2 > scale:
            notes.append(
                f"carrier motion not periodic at {self._order}/f_d (model error "
                f"{fit.model_error_rms_mps2:.3g} m/s^2): low confidence"
            )
        message = "; ".join(notes) if notes else "ok"
        freq = self._freq if self._freq is not None else nan
        if not math.isfinite(self._last_t) or fit is None or len(self._hist) == 0:
            no_input = not math.isfinite(self._last_t) and not self._events
            return VehicleEstimate(
                self._last_t if math.isfinite(self._last_t) else nan,
                nan, nan, nan, 0.0, PHASE_STICK, 0.0, nan, 0.0, nan, 0.0, nan, nan, 0.0, 0.0,
                Status.NO_INPUT if no_input else status,
                "no accelerometer samples yet" if no_input else message,
                freq, 0,
            )  # fmt: skip
        t_end = float(self._hist.col("t")[-1])
        k = self._belief.gain
        v_c, a_c = self._last_carrier
        u = self._observer.part_velocity_mps
        sigma_u = math.hypot(fit.velocity_uncertainty_mps / k, self._spread)
        window = self._window_statistics(t_end)
        return VehicleEstimate(
            t_s=t_end,
            carrier_velocity_mps=v_c / k,
            part_velocity_mps=u / k,
            part_velocity_uncertainty_mps=sigma_u,
            part_velocity_confidence=confidence(u / k, sigma_u),
            phase=self._observer.phase,
            phase_confidence=self._phaseconfidence(fit, t_end, v_c, a_c, u),
            advance_per_cycle_m=window.advance_m,
            advance_per_cycle_confidence=window.advance_confidence,
            slip_fraction=window.slip_fraction,
            slip_fraction_confidence=window.slip_confidence,
            mean_speed_mps=window.mean_speed_mps,
            mean_speed_uncertainty_mps=window.mean_speed_uncertainty_mps,
            mean_speed_confidence=confidence(
                window.mean_speed_mps, window.mean_speed_uncertainty_mps
            ),
            window_s=window.measured_s,
            status=status,
            status_message=message,
            drive_frequency_hz=freq,
            period_order=self._order,
        )

    def _phaseconfidence(
        self, fit: HarmonicFit, t_end: float, v_c: float, a_c: float, u: float
    ) -> float:
        """The phase's margin (distance to the stick limit, or relative velocity) in units of its
        uncertainty, times the fit's and the part state's quality."""
        cfg = self._cfg
        L = self._belief.measured_part().stick_limit_mps2
        q_fit = 1.0 / (1.0 + (fit.model_error_rms_mps2 / (cfg.model_error_scale * L)) ** 2)
        q_fill = min(1.0, fit.span_s / cfg.fit_window_s)
        q_obs = (
            min(1.0, (t_end - self._observer_start) / cfg.observer_settle_s)
            if cfg.observer_settle_s > 0.0
            else 1.0
        )
        if self._observer.phase == PHASE_STICK:
            margin = (L - abs(a_c)) / max(fit.acceleration_uncertainty_mps2, 1e-12)
        else:
            margin = abs(v_c - u) / max(fit.velocity_uncertainty_mps, 1e-12)
        return q_fit * q_fill * q_obs * 0.5 * (1.0 + math.erf(margin / math.sqrt(2.0)))

    def _window_statistics(self, t_end: float) -> WindowStatistics:
        """Mean speed, slip fraction and advance per cycle, valid only over a window that lies
        wholly after the current drive setting's carrier model converged (``steady_since_s``) and
        covers ``min_valid_window`` of ``window_s``; otherwise nan (status SETTLING)."""
        cfg = self._cfg
        k = self._belief.gain
        if not (math.isfinite(self._valid_from) and t_end > self._valid_from):
            return WindowStatistics()
        w_start = max(t_end - cfg.window_s, self._stats_start)
        tv = self._cumulative_at("time_valid", t_end) - self._cumulative_at("time_valid", w_start)
        if tv < cfg.min_valid_window * cfg.window_s - 1.5 * (self._dt_nominal or 0.0):
            return WindowStatistics(measured_s=max(tv, 0.0))
        if self._fit is not None:
            # whole response periods: within one, the part's position swings with the carrier, so
            # a mean over a fraction of one more period is off by that swing over the window
            period = 1.0 / self._fit.base_frequency_hz
            whole = math.floor((t_end - w_start) / period + 1e-9)
            if whole >= 1:
                w_start = t_end - whole * period
                tv = self._cumulative_at("time_valid", t_end)
                tv -= self._cumulative_at("time_valid", w_start)
        mean = (
            self._cumulative_at("x_valid", t_end) - self._cumulative_at("x_valid", w_start)
        ) / tv
        slip = (
            self._cumulative_at("slip_valid", t_end) - self._cumulative_at("slip_valid", w_start)
        ) / tv
        mean /= k
        sigma = math.sqrt(
            self._sigma_carrier**2 + self._sigma_part**2 + (cfg.method_uncertainty * mean) ** 2
        )
        window = WindowStatistics(
            mean_speed_mps=mean,
            mean_speed_uncertainty_mps=sigma,
            # a difference of running totals over their own span: round-off can leave [0, 1]
            slip_fraction=min(max(slip, 0.0), 1.0),
            slip_confidence=self._q_slip * min(1.0, tv / cfg.window_s),
            measured_s=tv,
        )
        if self._freq is None:
            return window
        period = 1.0 / self._freq
        c_start = t_end - period
        if c_start < max(float(self._hist.col("t")[0]), self._valid_from):
            return window
        advance = (self._cumulative_at("x_all", t_end) - self._cumulative_at("x_all", c_start)) / k
        return replace(
            window, advance_m=advance, advance_confidence=confidence(advance, sigma * period)
        )

    def _conditions(self) -> dict[Status, str]:
        """Conditions inside the current window, in priority order, with their messages."""
        cfg = self._cfg
        out: dict[Status, str] = {}
        t_end = self._last_t
        w_start = t_end - cfg.window_s
        while self._invalid and self._invalid[0][0] < w_start and math.isfinite(t_end):
            self._invalid.popleft()  # out of the window for good (stamps only grow)
        for status in (Status.OUT_OF_ORDER, Status.INVALID_SAMPLES, Status.GAP):
            when = self._events.get(status)
            if when is not None and (when >= w_start or not math.isfinite(t_end)):
                out[status] = self._event_notes[status]
        if Status.INVALID_SAMPLES in out:
            dropped = sum(n for _, n in self._invalid)
            out[Status.INVALID_SAMPLES] = f"{dropped} non-finite or out-of-range samples dropped"
        when = self._events.get(Status.DRIVE_CHANGED)
        if when is not None and when >= w_start:
            out[Status.DRIVE_CHANGED] = self._event_notes[Status.DRIVE_CHANGED]
        if math.isfinite(t_end):
            settling = self._settling(t_end)
            if settling:
                out[Status.SETTLING] = ", ".join(settling)
        return out

    def _settling(self, t_end: float) -> list[str]:
        """Why no mean speed is valid yet (empty once one is)."""
        cfg = self._cfg
        why = []
        if self._freq is None:
            why.append("estimating the drive frequency")
        fit = self._fit
        if fit is None:
            why.append("waiting for enough samples to fit the carrier")
        elif not math.isfinite(self._converged_t):
            if fit.span_s < 0.9 * cfg.fit_window_s:
                why.append("carrier fit window not full yet")
            limit = cfg.model_error_scale * cfg.part.stick_limit_mps2
            if fit.model_error_rms_mps2 > limit:
                why.append(
                    f"carrier model not converged (model error {fit.model_error_rms_mps2:.3g} > "
                    f"{limit:.3g} m/s^2: transient, or not periodic)"
                )
        if math.isfinite(self._valid_from):
            covered = t_end - max(self._valid_from, self._stats_start)
            needed = cfg.min_valid_window * cfg.window_s - 1.5 * (self._dt_nominal or 0.0)
            if t_end < self._valid_from:
                why.append("part state settling")
            elif covered < needed:
                why.append(f"statistics window filling ({max(covered, 0.0):.2g} of {needed:.2g} s)")
        return why


def load_kernels() -> None:
    """Run a throwaway estimator over 1.5 s of a synthetic 25 Hz carrier (1 kHz, pushes of 100
    samples): numba loads the estimator's compiled kernels (harmonic fit, stick-slip observer, the
    uncertainty runs) and Python its lazy imports now, not at a live stream's first samples. A node
    that loaded them there stopped publishing for 2-4 s at its start on a cold machine, and a speed
    monitor that had heard it once called that a sensor timeout."""
    estimator = VehicleEstimator()
    estimator.set_drive(25.0, 20.0, 0.0)
    t = np.arange(1500) * 1e-3
    a = 3.0 * np.sin(2.0 * math.pi * 25.0 * t) + 0.5 * np.sin(2.0 * math.pi * 75.0 * t)
    for k in range(0, t.size, 100):
        estimator.push(t[k : k + 100], a[k : k + 100])
    estimator.flush()
