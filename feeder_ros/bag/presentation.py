"""What ``feeder analyze`` shows a person, once, for the terminal and the HTML report alike.

:func:`sections` turns each feeder's :class:`~feeder_ros.bag.results.BagAnalysis` into a
:class:`Section`: a few lines about the bag, the headline figures (run time, parts fed, feed rate,
time at target, faults), and tables with human headers and units, every number rounded to what it
means (speeds to 0.01 mm/s, times to 0.1 s, shares to whole per cent). :func:`text_table` and
:func:`html_table` only lay the same cells out. Machine-readable files (CSV, JSON) keep full
precision and SI names; this module is for reading.

Times: seconds from the start of the feeder's recording; where the stamps are wall-clock time
(after 2001), also the clock time (UTC), which is what a shift log and a cell's alarm history use.
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime

from feeder_ros.bag.results import BagAnalysis
from feeder_ros.bag.run_log import RunFigures

__all__ = [
    "Column",
    "Fact",
    "Section",
    "Table",
    "clock",
    "comparison_table",
    "duration",
    "html_table",
    "sections",
    "status",
    "text_table",
]

_WALL_CLOCK_AFTER_NS = 1_000_000_000 * 1_000_000_000  # 2001-09-09: earlier stamps are sim time


@dataclass(frozen=True)
class Column:
    header: str  # with its unit: "speed [mm/s]"
    numeric: bool = True  # right-aligned, never broken
    wrap: bool = False  # text that may wrap anywhere (messages, names); other text stays whole


@dataclass
class Table:
    key: str  # a name for files and the page ("segments", "diagnostics", ...)
    title: str
    columns: list[Column]
    rows: list[list[str]]


@dataclass(frozen=True)
class Fact:
    """A headline figure: ``key`` names it for machines, ``label`` and ``value`` for people."""

    key: str
    label: str
    value: str


@dataclass
class Section:
    """One feeder of one bag (or a bag that could not be analysed: ``error``)."""

    title: str
    error: str = ""
    lines: list[str] = field(default_factory=list)  # what the bag is
    alerts: list[str] = field(default_factory=list)  # what it lost
    headline: list[Fact] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)


# ------------------------------------------------------------------------------ numbers


def number(value: float | None, pattern: str) -> str:
    """``value`` formatted, or "-" where there is none (None, NaN)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return pattern.format(value)


def duration(seconds: float) -> str:
    """``45.2 s``, ``12 min 05 s``, ``3 h 07 min``: as long as it needs to be read."""
    if math.isnan(seconds):
        return "-"
    if round(seconds, 1) < 60.0:
        return f"{seconds:.1f} s"
    whole = round(seconds)
    if whole < 3600:
        return f"{whole // 60} min {whole % 60:02d} s"
    return f"{whole // 3600} h {whole % 3600 // 60:02d} min"


def clock(start_ns: int | None, t_s: float) -> str:
    """The clock time (UTC) ``t_s`` seconds after ``start_ns``; "" for simulated time."""
    if start_ns is None or start_ns < _WALL_CLOCK_AFTER_NS or math.isnan(t_s):
        return ""
    moment = datetime.fromtimestamp(start_ns * 1e-9 + t_s, tz=UTC)
    return moment.strftime("%H:%M:%S")


def _mm(value_mps: float) -> str:
    return number(value_mps * 1e3, "{:.2f}")


def _off_target(actual_mps: float, target_mps: float) -> str:
    if math.isnan(actual_mps) or math.isnan(target_mps) or target_mps == 0.0:
        return "-"
    return f"{100.0 * (actual_mps - target_mps) / abs(target_mps):+.1f}"


# ------------------------------------------------------------------------------ content


def headline(figures: RunFigures) -> list[Fact]:
    """The figures a production engineer reads first."""
    facts = [
        Fact("run_time", "run time", duration(figures.run_s)),
        Fact("parts_fed", "parts fed", f"{figures.parts_fed:d}"),
        Fact("feed_rate", "mean feed rate", number(figures.feed_rate_per_min, "{:.1f} /min")),
    ]
    if not math.isnan(figures.driving_s):
        facts.append(Fact("driving_time", "drive on", duration(figures.driving_s)))
    if math.isnan(figures.target_s):
        facts.append(Fact("time_at_target", "time at target", "- (no speed/status recorded)"))
    elif figures.target_s <= 0.0:
        facts.append(Fact("time_at_target", "time at target", "- (no target while driving)"))
    else:
        share = f"{100.0 * figures.at_target_share:.0f} %"
        facts.append(
            Fact(
                "time_at_target",
                "time at target",
                f"{share} ({duration(figures.at_target_s)} of {duration(figures.target_s)})",
            )
        )
    total = sum(f.duration_s for f in figures.faults if not math.isnan(f.duration_s))
    open_ = any(math.isnan(f.duration_s) for f in figures.faults)
    faults = f"{len(figures.faults)}" + (f" ({duration(total)})" if figures.faults else "")
    facts.append(
        Fact("faults", "faults", faults + (", still in fault at the end" if open_ else ""))
    )
    return facts


def segment_table(a: BagAnalysis) -> Table:
    """Target against actual, segment by segment of constant drive."""
    columns = [
        Column("#"),
        Column("from [s]"),
        Column("to [s]"),
        Column("f [Hz]"),
        Column("A [N]"),
        Column("target [mm/s]"),
        Column("estimate [mm/s]"),
        Column("transits [mm/s]"),
        Column("truth [mm/s]"),
        Column("off target [%]"),
        Column("slip (est)"),
        Column("slip (truth)"),
        Column("exits"),
        Column("feed [/min]"),
    ]
    rows = [
        [
            str(s.index),
            f"{s.start_s:.1f}",
            f"{s.end_s:.1f}",
            number(s.frequency_hz, "{:.4g}") if s.enabled else "off",
            number(s.amplitude_n, "{:.3g}"),
            _mm(s.target_speed_mps),
            _mm(s.speed_estimate_mps),
            _mm(s.speed_sensors_mps),
            _mm(s.speed_ground_truth_mps),
            _off_target(s.speed_mps, s.target_speed_mps) if s.enabled else "-",
            number(s.slip_estimate, "{:.2f}"),
            number(s.slip_ground_truth, "{:.2f}"),
            str(s.parts_exited),
            number(s.feed_rate_per_min, "{:.1f}"),
        ]
        for s in a.segments
    ]
    return Table("segments", "Target against actual, per segment of constant drive", columns, rows)


def fault_table(a: BagAnalysis) -> Table | None:
    if a.figures is None or not a.figures.faults:
        return None
    rows = [
        [
            clock(a.start_ns, f.start_s) or "-",
            f"{f.start_s:.1f}",
            "until the end" if math.isnan(f.duration_s) else duration(f.duration_s),
            f.state,
            f.reason or "-",
        ]
        for f in a.figures.faults
    ]
    columns = [
        Column("clock (UTC)", numeric=False),
        Column("at [s]"),
        Column("lasted"),
        Column("state", numeric=False),
        Column("reason", numeric=False, wrap=True),
    ]
    return Table("faults", "Drive faults", columns, rows)


def diagnostics_table(a: BagAnalysis, limit: int | None = None) -> Table | None:
    if not a.diagnostics:
        return None
    shown = a.diagnostics if limit is None else a.diagnostics[:limit]
    # the section is the feeder's: its namespace need not be read again in every row
    prefix = f"{a.namespace.rstrip('/')}/" if a.namespace else ""
    rows = [
        [
            clock(a.start_ns, d.t_s) or "-",
            f"{d.t_s:.1f}",
            d.level_name,
            d.name.removeprefix(prefix) if prefix != "/" else d.name,
            d.message,
        ]
        for d in shown
    ]
    columns = [
        Column("clock (UTC)", numeric=False),
        Column("at [s]"),
        Column("level", numeric=False),
        Column("status", numeric=False, wrap=True),
        Column("message", numeric=False, wrap=True),
    ]
    title = "Diagnostics timeline (level changes)"
    if prefix not in ("", "/"):
        title = f"Diagnostics timeline (level changes; names under {prefix.rstrip('/')})"
    return Table("diagnostics", title, columns, rows)


def frequency_table(a: BagAnalysis) -> Table | None:
    if not a.frequency_response:
        return None
    rows = [
        [
            f"{p.amplitude_n:.3g}",
            f"{p.frequency_hz:.4g}",
            f"{p.duration_s:.1f}",
            _mm(p.speed_mps),
            number(p.slip_fraction, "{:.2f}"),
            number(p.feed_rate_per_min, "{:.1f}"),
        ]
        for p in a.frequency_response
    ]
    columns = [
        Column("A [N]"),
        Column("f [Hz]"),
        Column("time [s]"),
        Column("speed [mm/s]"),
        Column("slip"),
        Column("feed [/min]"),
    ]
    return Table("frequency_response", "Frequency response", columns, rows)


def _lost_topics(a: BagAnalysis) -> str:
    """The topics that lost messages, "/a/imu 20 of 500, ..." (with several feeders in the bag,
    this feeder's; the bag's total is in ``loss_summary``)."""
    if a.loss is None:
        return ""
    topics = [t for t in a.loss.lost_topics() if a.owns(t.topic)]
    return ", ".join(f"{t.topic} {t.lost} of {t.recorded}" for t in topics)


def section(a: BagAnalysis, diagnostics_limit: int | None = None) -> Section:
    if not a.ok:
        return Section(a.label, error=f"cannot analyse: {a.error}")
    out = Section(a.label)
    out.lines.append(
        f"{a.label}: {a.duration_s:.3f} s, drive from {a.drive_source}, "
        f"{len(a.segments)} segment(s)"
        + (f" (+{a.transient_segments} transient)" if a.transient_segments else "")
        + (", CUT SHORT (a file ends without its summary)" if a.cut_short else "")
    )
    started = clock(a.start_ns, 0.0)
    if started:
        assert a.start_ns is not None
        day = datetime.fromtimestamp(a.start_ns * 1e-9, tz=UTC).strftime("%Y-%m-%d")
        out.lines.append(f"  recorded from {day} {started} UTC")
    if a.data_lost:
        out.alerts.append(
            f"DATA LOST: {a.loss_summary()}: counts, exits and feed rates are short "
            "(see the problems below)"
        )
        lost_topics = _lost_topics(a)
        if lost_topics:
            out.alerts.append(f"lost per topic: {lost_topics}")
    elif a.loss is not None and not a.loss.exact:
        out.alerts.append(f"messages recorded: unknown ({'; '.join(a.loss.unknown)})")
    counts = ", ".join(f"{k.rsplit('/', 1)[-1]} {v}" for k, v in sorted(a.messages.items()))
    if counts:
        out.lines.append(f"  messages: {counts}")
    if a.figures is not None:
        out.headline = headline(a.figures)
    tables = [
        segment_table(a) if a.segments else None,
        fault_table(a),
        frequency_table(a),
        diagnostics_table(a, diagnostics_limit),
    ]
    out.tables = [t for t in tables if t is not None]
    if diagnostics_limit is not None and len(a.diagnostics) > diagnostics_limit:
        out.problems.append(
            f"{len(a.diagnostics) - diagnostics_limit} more diagnostic level changes "
            "(see the CSV/JSON)"
        )
    out.problems += a.problems
    return out


def sections(
    analyses: Sequence[BagAnalysis], diagnostics_limit: int | None = None
) -> list[Section]:
    return [section(a, diagnostics_limit) for a in analyses]


def status(a: BagAnalysis) -> str:
    """One word for a bag: error, data lost, cut short or ok."""
    if not a.ok:
        return "error"
    if a.data_lost:
        return "data lost"
    return "cut short" if a.cut_short else "ok"


def comparison_table(analyses: Sequence[BagAnalysis]) -> Table:
    rows = []
    for a in analyses:
        totals = a.totals() if a.ok else {}
        figures = a.figures
        rows.append(
            [
                a.label,
                status(a),
                duration(totals.get("duration_s", math.nan)),
                str(len(a.segments)),
                _mm(totals.get("speed_mps", math.nan)),
                number(totals.get("slip_fraction", math.nan), "{:.2f}"),
                str(int(totals.get("parts_exited", 0))),
                number(totals.get("feed_rate_per_min", math.nan), "{:.1f}"),
                "-" if figures is None else number(100.0 * figures.at_target_share, "{:.0f}"),
            ]
        )
    columns = [
        Column("bag", numeric=False, wrap=True),
        Column("status", numeric=False),
        Column("time"),
        Column("segments"),
        Column("speed [mm/s]"),
        Column("slip"),
        Column("exits"),
        Column("feed [/min]"),
        Column("at target [%]"),
    ]
    return Table("comparison", "Comparison", columns, rows)


# ------------------------------------------------------------------------------ layouts


def text_table(table: Table, indent: str = "  ") -> str:
    """Columns padded to their widest cell: numbers right, text left."""
    headers = [c.header for c in table.columns]
    widths = [max(len(h), *(len(r[i]) for r in table.rows)) for i, h in enumerate(headers)]

    def line(cells: Sequence[str]) -> str:
        padded = [
            cell.rjust(w) if column.numeric else cell.ljust(w)
            for cell, w, column in zip(cells, widths, table.columns, strict=True)
        ]
        return (indent + "  ".join(padded)).rstrip()

    out = [line(headers), indent + "  ".join("-" * w for w in widths)]
    return "\n".join(out + [line(r) for r in table.rows])


def html_table(table: Table) -> str:
    """A table whose numbers align right and whose text wraps within the page."""
    kinds = ["num" if c.numeric else "wrap" if c.wrap else "text" for c in table.columns]
    head = "".join(
        f"<th class='{k}'>{html.escape(c.header)}</th>"
        for c, k in zip(table.columns, kinds, strict=True)
    )
    body = "".join(
        "<tr>"
        + "".join(f"<td class='{k}'>{html.escape(v)}</td>" for v, k in zip(r, kinds, strict=True))
        + "</tr>"
        for r in table.rows
    )
    return (
        f"<table data-table='{html.escape(table.key)}'><thead><tr>{head}</tr></thead>"
        f"<tbody>{body}</tbody></table>"
    )
