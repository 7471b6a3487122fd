"""The report's pictures of one feeder (PNG, matplotlib's Agg backend): part speed and the drive
over time (``speed/status``, ``drive/state``; long runs as min-max envelopes), speed and slip per
segment, and the frequency response of a sweep."""

from __future__ import annotations

import io
import math
from typing import Any

import numpy as np

from feeder_ros.bag.results import BagAnalysis
from feeder_ros.figures import envelope

__all__ = ["plots"]

_COLORS = {"ground truth": "C0", "sensor transits": "C1", "estimator": "C2"}


def plots(a: BagAnalysis) -> dict[str, bytes]:
    """PNG images of one feeder: speed and drive over time (when the bag has speed/status or
    drive/state), speed and slip per segment, the frequency response (a sweep)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    images: dict[str, bytes] = {}
    timeline = _timeline(a)
    if timeline is not None:
        images["timeline"] = _png(timeline)
    if any(not math.isnan(s.speed_mps) or not math.isnan(s.slip_fraction) for s in a.segments):
        fig = Figure(figsize=(8, 5), layout="constrained")
        ax_speed, ax_slip = fig.subplots(2, 1, sharex=True)
        for label, attr in (
            ("ground truth", "speed_ground_truth_mps"),
            ("sensor transits", "speed_sensors_mps"),
            ("estimator", "speed_estimate_mps"),
        ):
            xs: list[float] = []
            ys: list[float] = []
            for s in a.segments:
                xs += [s.start_s, s.end_s, math.nan]
                v = getattr(s, attr) * 1e3
                ys += [v, v, math.nan]
            if any(not math.isnan(y) for y in ys):
                ax_speed.plot(xs, ys, label=label, color=_COLORS[label])
        ax_speed.set_ylabel("mean part speed [mm/s]")
        if ax_speed.lines:
            ax_speed.legend(loc="best", fontsize="small")
        ax_speed.set_title(f"{a.name}: segments of constant drive")
        for label, attr in (("ground truth", "slip_ground_truth"), ("estimator", "slip_estimate")):
            xs, ys = [], []
            for s in a.segments:
                xs += [s.start_s, s.end_s, math.nan]
                ys += [getattr(s, attr)] * 2 + [math.nan]
            if any(not math.isnan(y) for y in ys):
                ax_slip.plot(xs, ys, label=label, color=_COLORS[label])
        if ax_slip.lines:
            ax_slip.legend(loc="best", fontsize="small")
        ax_slip.set_ylabel("slip fraction")
        ax_slip.set_xlabel("time [s]")
        images["segments"] = _png(fig)
    if any(not math.isnan(p.speed_mps) for p in a.frequency_response):
        fig = Figure(figsize=(8, 4), layout="constrained")
        ax = fig.subplots()
        for amp in sorted({p.amplitude_n for p in a.frequency_response}):
            pts = [p for p in a.frequency_response if p.amplitude_n == amp]
            ax.plot(
                [p.frequency_hz for p in pts],
                [p.speed_mps * 1e3 for p in pts],
                marker="o",
                label=f"A = {amp:g} N",
            )
        ax.set_xlabel("drive frequency [Hz]")
        ax.set_ylabel("mean part speed [mm/s]")
        ax.set_title(f"{a.name}: frequency response")
        ax.legend(loc="best", fontsize="small")
        images["frequency_response"] = _png(fig)
    return images


def _png(fig: Any) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100)
    return buffer.getvalue()


def _line(ax: Any, t: Any, y: Any, **style: Any) -> None:
    """``y`` over ``t``; a long series as the middle of its min-max envelope; nothing when ``y``
    has no value (a stream without it)."""
    if not np.isfinite(y).any():
        return
    tm, low, high = envelope(t, y)
    ax.plot(tm, 0.5 * (low + high), **style)


def _timeline(a: BagAnalysis) -> Any | None:
    """Part speed (target, estimate with its 2-sigma band, transits, truth per segment) and the
    drive (frequency, amplitude, faults shaded) over the run."""
    from matplotlib.figure import Figure

    speed, drive = a.speed_status, a.drive_state
    if (speed is None and drive is None) or a.start_ns is None:
        return None
    start = a.start_ns
    fig = Figure(figsize=(10, 6), layout="constrained")
    ax_speed, ax_drive = fig.subplots(2, 1, sharex=True)
    if speed is not None:
        t = (speed.t_ns - start) * 1e-9
        est = speed["estimated_speed_mps"].astype(np.float64) * 1e3
        two_sigma = 2.0 * speed["estimated_speed_uncertainty_mps"].astype(np.float64) * 1e3
        tm, low, _ = envelope(t, est - two_sigma)
        _, _, high = envelope(t, est + two_sigma)
        ax_speed.fill_between(
            tm, low, high, color="C2", alpha=0.25, linewidth=0, label="estimate +- 2 sigma"
        )
        _line(ax_speed, t, est, color="C2", linewidth=1.0, label="estimate")
        _line(ax_speed, t, speed["transit_speed_mps"].astype(np.float64) * 1e3, color="C1",
              linewidth=1.0, label="sensor transits")  # fmt: skip
        target = speed["target_speed_mps"].astype(np.float64) * 1e3
        ax_speed.step(t, target, where="post", color="k", linestyle="--", linewidth=1.0,
                      label="target")  # fmt: skip
    truth_x: list[float] = []
    truth_y: list[float] = []
    for s in a.segments:
        truth_x += [s.start_s, s.end_s, math.nan]
        truth_y += [s.speed_ground_truth_mps * 1e3] * 2 + [math.nan]
    if any(not math.isnan(y) for y in truth_y):
        ax_speed.plot(truth_x, truth_y, color="C0", linewidth=2.0, label="truth (segment mean)")
    ax_speed.set_ylabel("part speed [mm/s]")
    if ax_speed.lines:
        ax_speed.legend(loc="upper right", fontsize="small")
    ax_speed.set_title(f"{a.name}: part speed and drive over time")
    if drive is not None:
        t = (drive.t_ns - start) * 1e-9
        _line(ax_drive, t, drive["frequency_hz"].astype(np.float64), color="C3", linewidth=1.0)
        ax_drive.set_ylabel("frequency [Hz]", color="C3")
        ax_amplitude = ax_drive.twinx()
        _line(ax_amplitude, t, drive["amplitude_percent"].astype(np.float64), color="C4",
              linewidth=1.0)  # fmt: skip
        ax_amplitude.set_ylabel("amplitude [%]", color="C4")
    if a.figures is not None:
        for k, fault in enumerate(a.figures.faults):
            end = fault.end_s if not math.isnan(fault.end_s) else a.duration_s
            for ax in (ax_speed, ax_drive):
                ax.axvspan(fault.start_s, end, color="red", alpha=0.15, linewidth=0,
                           label="drive fault" if k == 0 and ax is ax_drive else None)  # fmt: skip
        if a.figures.faults:
            ax_drive.legend(loc="upper right", fontsize="small")
    ax_drive.set_xlabel("time since the recording began [s]")
    return fig
