"""Presentation of :mod:`feeder_ros.bag.analysis` results: terminal tables, CSV, JSON, PNG plots
(matplotlib, Agg backend) and one self-contained HTML report (images embedded as base64).

One section per analysed feeder. A bag holding several feeders gives one section per feeder,
headed ``<bag> [<namespace>]``, and one set of files each, named ``<bag>_<namespace>_*``
(``/cell/feeder_a`` -> ``bag_cell_feeder_a_segments.csv``); ``comparison.csv`` and
``analysis.json`` have a ``namespace`` column / key. What the bag lost is given as a count of
messages (recorded, lost; per topic in the JSON)."""

from __future__ import annotations

import base64
import csv
import html
import io
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from feeder_ros.atomic_files import atomic_bytes
from feeder_ros.bag.analysis import BagAnalysis

__all__ = ["comparison_rows", "format_summary", "segment_rows", "write_outputs"]

SEGMENT_COLUMNS = [
    ("start [s]", "start_s", "{:.3f}"),
    ("end [s]", "end_s", "{:.3f}"),
    ("f [Hz]", "frequency_hz", "{:g}"),
    ("A [N]", "amplitude_n", "{:g}"),
    ("speed [mm/s]", "speed_mm_s", "{:.4g}"),
    ("speed est [mm/s]", "speed_estimate_mm_s", "{:.4g}"),
    ("speed truth [mm/s]", "speed_ground_truth_mm_s", "{:.4g}"),
    ("speed sensors [mm/s]", "speed_sensors_mm_s", "{:.4g}"),
    ("slip est", "slip_estimate", "{:.3f}"),
    ("slip truth", "slip_ground_truth", "{:.3f}"),
    ("exits", "parts_exited", "{:d}"),
    ("feed [1/min]", "feed_rate_per_min", "{:.3g}"),
]


def _fmt(value: Any, pattern: str) -> str:
    if value is None:
        return "-"
    if isinstance(value, float) and math.isnan(value):
        return "-"
    return pattern.format(value)


def segment_rows(analysis: BagAnalysis) -> list[dict[str, Any]]:
    rows = []
    for s in analysis.segments:
        rows.append(
            {
                "segment": s.index,
                "start_s": s.start_s,
                "end_s": s.end_s,
                "frequency_hz": s.frequency_hz,
                "amplitude_n": s.amplitude_n,
                "speed_mm_s": s.speed_mps * 1e3,
                "speed_estimate_mm_s": s.speed_estimate_mps * 1e3,
                "speed_ground_truth_mm_s": s.speed_ground_truth_mps * 1e3,
                "speed_sensors_mm_s": s.speed_sensors_mps * 1e3,
                "transits": s.transits,
                "transits_left_out": s.transits_left_out,
                "slip_estimate": s.slip_estimate,
                "slip_ground_truth": s.slip_ground_truth,
                "parts_exited": s.parts_exited,
                "feed_rate_per_min": s.feed_rate_per_min,
            }
        )
    return rows


def comparison_rows(analyses: Sequence[BagAnalysis]) -> list[dict[str, Any]]:
    rows = []
    for a in analyses:
        totals = a.totals() if a.ok else {}
        rows.append(
            {
                "bag": str(a.path),
                "namespace": a.namespace or "",
                "status": _status(a),
                "duration_s": totals.get("duration_s", math.nan),
                "segments": len(a.segments),
                "speed_mm_s": totals.get("speed_mps", math.nan) * 1e3,
                "slip_fraction": totals.get("slip_fraction", math.nan),
                "parts_exited": int(totals.get("parts_exited", 0)),
                "feed_rate_per_min": totals.get("feed_rate_per_min", math.nan),
                "lost_messages": "" if a.loss is None else a.loss.lost,
                "problems": len(a.problems),
                "error": a.error or "",
            }
        )
    return rows


def _lost_topics(a: BagAnalysis) -> str:
    """The topics that lost messages, "/a/imu 20 of 500, ..." (with several feeders in the bag,
    this feeder's; the bag's total is in ``loss_summary``)."""
    if a.loss is None:
        return ""
    topics = [t for t in a.loss.lost_topics() if a.owns(t.topic)]
    return ", ".join(f"{t.topic} {t.lost} of {t.recorded}" for t in topics)


def _status(a: BagAnalysis) -> str:
    if not a.ok:
        return "error"
    if a.data_lost:
        return "data lost"
    return "cut short" if a.cut_short else "ok"


def _table(headers: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(headers)]
    line = "  ".join(h.rjust(w) for h, w in zip(headers, widths, strict=True))
    out = [line, "  ".join("-" * w for w in widths)]
    out += ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    return "\n".join(out)


def format_summary(analyses: Sequence[BagAnalysis]) -> str:
    """The terminal summary: per bag its segments, sweep and diagnostics, then a comparison."""
    parts: list[str] = []
    for a in analyses:
        if not a.ok:
            parts.append(f"{a.label}: cannot analyse: {a.error}")
            continue
        head = (
            f"{a.label}: {a.duration_s:.3f} s, drive from {a.drive_source}, "
            f"{len(a.segments)} segment(s)"
            + (f" (+{a.transient_segments} transient)" if a.transient_segments else "")
            + (", CUT SHORT (a file ends without its summary)" if a.cut_short else "")
        )
        parts.append(head)
        if a.data_lost:
            parts.append(
                f"  DATA LOST: {a.loss_summary()}: counts, exits and feed rates are short "
                "(see the problems below)"
            )
            lost_topics = _lost_topics(a)
            if lost_topics:
                parts.append(f"  lost per topic: {lost_topics}")
        elif a.loss is not None and not a.loss.exact:
            parts.append(f"  messages recorded: unknown ({'; '.join(a.loss.unknown)})")
        counts = ", ".join(f"{k.rsplit('/', 1)[-1]} {v}" for k, v in sorted(a.messages.items()))
        if counts:
            parts.append(f"  messages: {counts}")
        if a.segments:
            rows = segment_rows(a)
            parts.append(
                _table(
                    ["#"] + [c[0] for c in SEGMENT_COLUMNS],
                    [
                        [str(r["segment"])] + [_fmt(r[key], pat) for _, key, pat in SEGMENT_COLUMNS]
                        for r in rows
                    ],
                )
            )
        if a.frequency_response:
            parts.append("  frequency response:")
            parts.append(
                _table(
                    ["A [N]", "f [Hz]", "time [s]", "speed [mm/s]", "slip", "feed [1/min]"],
                    [
                        [
                            f"{p.amplitude_n:g}",
                            f"{p.frequency_hz:g}",
                            f"{p.duration_s:.2f}",
                            _fmt(p.speed_mps * 1e3, "{:.4g}"),
                            _fmt(p.slip_fraction, "{:.3f}"),
                            _fmt(p.feed_rate_per_min, "{:.3g}"),
                        ]
                        for p in a.frequency_response
                    ],
                )
            )
        if a.diagnostics:
            parts.append("  diagnostics (level changes):")
            parts += [
                f"    {d.t_s:10.3f} s  {d.level_name:<5}  {d.name}: {d.message}"
                for d in a.diagnostics[:50]
            ]
            if len(a.diagnostics) > 50:
                parts.append(f"    ... {len(a.diagnostics) - 50} more (see the CSV/JSON)")
        for problem in a.problems:
            parts.append(f"  problem: {problem}")
    if len(analyses) > 1:
        parts.append("comparison:")
        rows = comparison_rows(analyses)
        parts.append(
            _table(
                ["bag", "status", "time [s]", "segments", "speed [mm/s]", "slip", "exits", "feed"],
                [
                    [
                        r["bag"] + (f" [{r['namespace']}]" if r["namespace"] else ""),
                        r["status"],
                        _fmt(r["duration_s"], "{:.2f}"),
                        str(r["segments"]),
                        _fmt(r["speed_mm_s"], "{:.4g}"),
                        _fmt(r["slip_fraction"], "{:.3f}"),
                        str(r["parts_exited"]),
                        _fmt(r["feed_rate_per_min"], "{:.3g}"),
                    ]
                    for r in rows
                ],
            )
        )
    return "\n".join(parts)


# ------------------------------------------------------------------------------ files


def _csv(rows: Sequence[dict[str, Any]], columns: Sequence[str] | None = None) -> bytes:
    buffer = io.StringIO()
    names = list(columns if columns is not None else (rows[0].keys() if rows else []))
    writer = csv.DictWriter(buffer, fieldnames=names, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: ("" if v is None else v) for k, v in row.items()})
    return buffer.getvalue().encode()


def _json_safe(value: Any) -> Any:
    if isinstance(value, float):
        return None if math.isnan(value) or math.isinf(value) else value
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    return value


def _stems(analyses: Sequence[BagAnalysis]) -> list[str]:
    stems: list[str] = []
    for a in analyses:
        base = "".join(c if c.isalnum() or c in "-_." else "_" for c in a.name) or "bag"
        stem, k = base, 2
        while stem in stems:
            stem, k = f"{base}-{k}", k + 1
        stems.append(stem)
    return stems


_COLORS = {"ground truth": "C0", "sensor transits": "C1", "estimator": "C2"}


def _plots(a: BagAnalysis) -> dict[str, bytes]:
    """PNG images of one bag: speed and slip per segment; the frequency response."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    images: dict[str, bytes] = {}
    if a.segments:
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
    if a.frequency_response:
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


def _html_table(rows: Sequence[dict[str, Any]]) -> str:
    if not rows:
        return "<p>(none)</p>"
    head = "".join(f"<th>{html.escape(str(k))}</th>" for k in rows[0])
    body = []
    for r in rows:
        cells = []
        for v in r.values():
            text = _fmt(v, "{:.6g}") if isinstance(v, float) else ("-" if v is None else str(v))
            cells.append(f"<td>{html.escape(text)}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table><tr>{head}</tr>{''.join(body)}</table>"


def write_outputs(analyses: Sequence[BagAnalysis], directory: Path) -> list[Path]:
    """Write CSV tables, ``analysis.json``, PNG plots and ``report.html`` into ``directory``."""
    directory.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []

    def put(name: str, data: bytes) -> None:
        path = directory / name
        atomic_bytes(path, data)
        written.append(path)

    sections: list[str] = []
    for stem, a in zip(_stems(analyses), analyses, strict=True):
        sections.append(f"<h2>{html.escape(a.label)}</h2>")
        if not a.ok:
            sections.append(f"<p class='error'>cannot analyse: {html.escape(a.error or '')}</p>")
            continue
        sections.append(
            f"<p>{a.duration_s:.3f} s; drive from {html.escape(a.drive_source)}; "
            f"{len(a.segments)} segment(s)" + (", <b>cut short</b>" if a.cut_short else "") + "</p>"
        )
        if a.data_lost:
            lost_topics = _lost_topics(a)
            sections.append(
                f"<p class='error'><b>Data lost</b>: {html.escape(a.loss_summary())}: counts, "
                "exits and feed rates are short"
                + (f" (per topic: {html.escape(lost_topics)})" if lost_topics else "")
                + ".</p>"
            )
        rows = segment_rows(a)
        put(f"{stem}_segments.csv", _csv(rows))
        sections += ["<h3>Segments</h3>", _html_table(rows)]
        if a.frequency_response:
            fr = [
                {
                    "amplitude_n": p.amplitude_n,
                    "frequency_hz": p.frequency_hz,
                    "duration_s": p.duration_s,
                    "speed_mm_s": p.speed_mps * 1e3,
                    "slip_fraction": p.slip_fraction,
                    "feed_rate_per_min": p.feed_rate_per_min,
                }
                for p in a.frequency_response
            ]
            put(f"{stem}_frequency_response.csv", _csv(fr))
            sections += ["<h3>Frequency response</h3>", _html_table(fr)]
        diag = [
            {"t_s": d.t_s, "name": d.name, "level": d.level_name, "message": d.message}
            for d in a.diagnostics
        ]
        if diag:
            put(f"{stem}_diagnostics.csv", _csv(diag))
            sections += ["<h3>Diagnostics (level changes)</h3>", _html_table(diag)]
        for kind, png in _plots(a).items():
            put(f"{stem}_{kind}.png", png)
            encoded = base64.b64encode(png).decode()
            sections.append(f"<img alt='{kind}' src='data:image/png;base64,{encoded}'>")
        if a.problems:
            sections.append("<h3>Problems</h3><ul>")
            sections += [f"<li>{html.escape(p)}</li>" for p in a.problems]
            sections.append("</ul>")
    comparison = comparison_rows(analyses)
    put("comparison.csv", _csv(comparison))
    if len(analyses) > 1:
        sections += ["<h2>Comparison</h2>", _html_table(comparison)]
    document = {"bags": [_json_safe(a.as_dict()) for a in analyses]}
    put("analysis.json", (json.dumps(document, indent=1) + "\n").encode())
    page = (
        "<!DOCTYPE html><html><head><meta charset='utf-8'><title>feeder analyze</title><style>"
        "body{font-family:sans-serif;margin:2em}table{border-collapse:collapse}"
        "td,th{border:1px solid #bbb;padding:2px 6px;text-align:right}"
        ".error{color:#b00}img{max-width:100%}</style></head><body><h1>Feeder bag analysis</h1>"
        + "\n".join(sections)
        + "</body></html>\n"
    )
    put("report.html", page.encode())
    return written
