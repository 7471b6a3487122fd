"""The paper's case study (Section 4, Fig. 8): its checkable facts and equivalent figures.

:func:`case_study_facts` runs the exact engine on the case-study parameters and reports what the
paper states and can be checked (MODEL-NOTES): the natural frequencies (32.93 Hz forward, 6.34 Hz
backward with ``M_p = 0.05 kg``), whether the part slips (not at A = 0.4 N, in both directions at A
= 40 N) and the first slip onset (about 3 ms at A = 40 N). :func:`plot_case_study` draws the Fig. 8
equivalents: carrier displacement over the run, phase portrait, and over the first 40 ms the carrier
acceleration against the slip threshold ``±mu_s*g*kappa`` with the part's position and phase.

Figures use matplotlib's object-oriented API with the Agg canvas (PNG, no display, no pyplot state).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
from matplotlib.figure import Figure

from feeder_ros.figures import envelope, save_figure
from feeder_ros.physics.parameters import FeederParameters
from feeder_ros.physics.simulation import EventKind, PartSpec, SimulationResult, simulate

__all__ = [
    "CASE_STUDY_AMPLITUDES_N",
    "CaseStudyFacts",
    "case_study_facts",
    "case_study_facts_from_result",
    "detail_run",
    "plot_case_study",
    "plot_result",
    "window_speeds",
]

CASE_STUDY_AMPLITUDES_N = (0.4, 40.0)
DETAIL_WINDOW_S = 0.04  # Fig. 8c/8d: the first 40 ms
PHASE_NAMES = {0: "stick", 1: "slip fwd", 2: "slip back"}


@dataclass(frozen=True)
class CaseStudyFacts:
    """What the paper's case study states that a simulation can check."""

    forward_natural_frequency_hz: float
    backward_natural_frequency_hz: float
    stick_limit_mps2: float  # mu_s*g*kappa
    peak_carrier_acceleration_mps2: float  # max |a| over the run
    slips: bool  # part 0 left STICK at least once
    slips_both_ways: bool  # ... in both directions
    first_slip_onset_s: float | None  # first STICK -> slip transition of part 0


def _slip_onsets(result: SimulationResult, part: int = 0) -> npt.NDArray[np.float64]:
    """Times at which ``part`` leaves STICK (from the event log)."""
    mask = (result.event_part == part) & (result.event_kind == int(EventKind.SLIP_START))
    return np.asarray(result.event_t_s[mask], dtype=np.float64)


def case_study_facts_from_result(
    params: FeederParameters, result: SimulationResult
) -> CaseStudyFacts:
    """The facts for an existing simulation result (its part 0)."""
    has_part = result.part_phase.ndim == 2 and result.part_phase.shape[1] > 0
    onsets = _slip_onsets(result) if has_part else np.zeros(0)
    phases = set(np.unique(result.part_phase[:, 0]).tolist()) if has_part else set()
    return CaseStudyFacts(
        forward_natural_frequency_hz=params.forward_natural_frequency_hz,
        backward_natural_frequency_hz=params.backward_natural_frequency_hz,
        stick_limit_mps2=params.stick_limit_mps2,
        peak_carrier_acceleration_mps2=float(np.abs(result.carrier_a_mps2).max()),
        slips=bool(onsets.size),
        slips_both_ways={1, 2} <= phases,
        first_slip_onset_s=float(onsets[0]) if onsets.size else None,
    )


def case_study_facts(
    amplitude_n: float, duration_s: float = 0.1, params: FeederParameters | None = None
) -> CaseStudyFacts:
    """Run the case study (one part, 1 ms output) at drive amplitude ``amplitude_n``."""
    base = params if params is not None else FeederParameters()
    params = base.with_changes(drive_amplitude_n=amplitude_n)
    result = simulate(params, duration_s, 1000.0, parts=(PartSpec(),))
    return case_study_facts_from_result(params, result)


def detail_run(
    params: FeederParameters, parts: Sequence[PartSpec] = (PartSpec(),), duration_s: float = 0.04
) -> SimulationResult:
    """The first ``duration_s`` (40 ms) sampled at 20 kHz, for the detail figure (Fig. 8c/8d)."""
    return simulate(params, duration_s, 20000.0, parts=parts)


def plot_result(
    result: SimulationResult,
    params: FeederParameters,
    out_dir: Path,
    prefix: str = "",
    detail: SimulationResult | None = None,
) -> list[Path]:
    """Fig. 8-style figures for one result: displacement (its envelope over a long run), phase
    portrait, first-40-ms detail; with parts, their track position and speed over the run.

    ``detail`` (e.g. :func:`detail_run`) is drawn in the detail figure instead of ``result``'s
    first 40 ms, so that events show at their true instants rather than at the next sample.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    label = f"A = {params.drive_amplitude_n:g} N"
    t = result.t_s
    paths: list[Path] = []

    fig = Figure(figsize=(8, 3.5), layout="constrained")
    ax = fig.add_subplot()
    middle, lowest, highest = envelope(t, result.carrier_x_m * 1e6)
    if middle.size < t.size:  # a long run: its envelope (a line would be a solid block)
        ax.fill_between(middle, lowest, highest, lw=0.0, alpha=0.6, label="min-max envelope")
        ax.legend(loc="upper right", fontsize="small")
    else:
        ax.plot(t, result.carrier_x_m * 1e6, lw=0.5)
    ax.set(xlabel="t [s]", ylabel="carrier displacement v [µm]", title=f"Carrier ({label})")
    paths.append(save_figure(fig, out_dir / f"{prefix}carrier_displacement.png"))
    whole = result

    fig = Figure(figsize=(5, 5), layout="constrained")
    ax = fig.add_subplot()
    ax.plot(result.carrier_x_m * 1e6, result.carrier_v_mps * 1e3, lw=0.3)
    ax.set(xlabel="v [µm]", ylabel="dv/dt [mm/s]", title=f"Phase portrait ({label})")
    paths.append(save_figure(fig, out_dir / f"{prefix}phase_portrait.png"))

    if detail is not None:
        result, t = detail, detail.t_s
    window = t <= DETAIL_WINDOW_S + 1e-12
    fig = Figure(figsize=(8, 7), layout="constrained")
    ax_a, ax_x, ax_p = fig.subplots(3, 1, sharex=True)
    limit = params.stick_limit_mps2
    ax_a.plot(t[window] * 1e3, result.carrier_a_mps2[window], label="carrier acceleration")
    ax_a.axhline(limit, color="r", ls="--", label="±mu_s*g*kappa")
    ax_a.axhline(-limit, color="r", ls="--")
    ax_a.set(ylabel="a [m/s²]", title=f"First {DETAIL_WINDOW_S * 1e3:g} ms ({label})")
    ax_a.legend(loc="upper right", fontsize="small")
    ax_x.plot(t[window] * 1e3, result.carrier_x_m[window] * 1e6, label="carrier")
    has_part = result.part_x_m.ndim == 2 and result.part_x_m.shape[1] > 0
    if has_part:
        offset = result.part_x_m[0, 0]
        ax_x.plot(
            t[window] * 1e3, (result.part_x_m[window, 0] - offset) * 1e6, "--", label="part 0"
        )
        ax_p.step(t[window] * 1e3, result.part_phase[window, 0], where="post")
    ax_x.set(ylabel="displacement [µm]")
    ax_x.legend(loc="upper right", fontsize="small")
    ax_p.set(xlabel="t [ms]", ylabel="part 0 phase", yticks=list(PHASE_NAMES))
    ax_p.set_yticklabels(list(PHASE_NAMES.values()))
    paths.append(save_figure(fig, out_dir / f"{prefix}first_40ms.png"))
    if whole.part_x_m.ndim == 2 and whole.part_x_m.shape[1] > 0 and whole.t_s.size > 1:
        paths.append(_plot_parts(whole, label, out_dir / f"{prefix}parts_over_run.png"))
    return paths


#: parts drawn in the parts figure at most (the first ones)
PLOTTED_PARTS = 10


def window_speeds(
    t: npt.NDArray[np.float64], track: npt.NDArray[np.float64], windows: int = 100
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """``(t_edges, speed)``: each part's mean speed along the track over ``windows`` equal spans
    of the run (speed (windows, k) in m/s from the track positions ``track`` (n, k) at the sorted
    times ``t`` (n,); NaN over a span in which the part was not on the track throughout). Spans
    are whole samples: at least one sample interval each."""
    n = t.size
    edges = np.unique(np.linspace(0, n - 1, min(windows, n - 1) + 1).round().astype(np.int64))
    dt = np.diff(t[edges])
    return t[edges], np.diff(track[edges], axis=0) / dt[:, None]


def _plot_parts(result: SimulationResult, label: str, path: Path) -> Path:
    """Track position and mean speed of the first :data:`PLOTTED_PARTS` parts over the run."""
    t = result.t_s
    count = result.part_x_m.shape[1]
    shown = min(count, PLOTTED_PARTS)
    track = result.part_x_m[:, :shown] - result.carrier_x_m[:, None]
    fig = Figure(figsize=(8, 6), layout="constrained")
    ax_x, ax_v = fig.subplots(2, 1, sharex=True)
    middle, lowest, highest = envelope(t, track * 1e3)
    edges, speeds = window_speeds(t, track)
    for k in range(shown):
        ax_x.plot(middle, 0.5 * (lowest[:, k] + highest[:, k]), lw=1.0, label=f"part {k}")
        ax_v.stairs(speeds[:, k] * 1e3, edges, lw=1.0, baseline=None)
    which = f"the first {shown} of {count} parts" if shown < count else f"{count} part(s)"
    ax_x.set(ylabel="track position [mm]", title=f"Parts over the run ({which}, {label})")
    if shown > 1:
        ax_x.legend(loc="upper left", fontsize="small", ncols=2)
    span = (edges[-1] - edges[0]) / max(edges.size - 1, 1)
    ax_v.set(xlabel="t [s]", ylabel=f"mean speed over {span:.3g} s [mm/s]")
    ax_v.axhline(0.0, color="0.6", lw=0.5)
    ax_v.set_xlim(t[0], t[-1])  # the whole run, as the carrier figure
    return save_figure(fig, path)


def plot_case_study(
    out_dir: Path,
    duration_s: float = 100.0,
    amplitudes_n: Sequence[float] = CASE_STUDY_AMPLITUDES_N,
    params: FeederParameters | None = None,
) -> list[Path]:
    """Fig. 8 equivalents for each amplitude (default 0.4 N and 40 N over 100 s, 1 ms output)."""
    base = params if params is not None else FeederParameters()
    paths: list[Path] = []
    for amplitude in amplitudes_n:
        run_params = base.with_changes(drive_amplitude_n=amplitude)
        result = simulate(run_params, duration_s, 1000.0, parts=(PartSpec(),))
        paths += plot_result(
            result, run_params, out_dir, prefix=f"A{amplitude:g}N_", detail=detail_run(run_params)
        )
    return paths
