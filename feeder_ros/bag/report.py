"""``feeder analyze``'s outputs: the terminal summary, CSV, JSON, PNG plots and one self-contained
HTML report (images embedded as base64). The summary and the report lay out the same sections
(:mod:`feeder_ros.bag.presentation`); the plots are :mod:`feeder_ros.bag.report_plots`'.

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
from feeder_ros.bag import presentation, report_plots
from feeder_ros.bag.analysis import BagAnalysis
from feeder_ros.bag.presentation import Section

_TERMINAL_DIAGNOSTICS = 50  # level changes listed in the terminal (all of them in the report)

__all__ = ["comparison_rows", "format_summary", "segment_rows", "write_outputs"]


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
                "target_speed_mm_s": s.target_speed_mps * 1e3,
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
                "status": presentation.status(a),
                "duration_s": totals.get("duration_s", math.nan),
                "segments": len(a.segments),
                "speed_mm_s": totals.get("speed_mps", math.nan) * 1e3,
                "slip_fraction": totals.get("slip_fraction", math.nan),
                "parts_exited": int(totals.get("parts_exited", 0)),
                "feed_rate_per_min": totals.get("feed_rate_per_min", math.nan),
                "lost_messages": "" if a.loss is None else a.loss.lost,
                "at_target_percent": math.nan
                if a.figures is None
                else 100.0 * a.figures.at_target_share,
                "problems": len(a.problems),
                "error": a.error or "",
            }
        )
    return rows


def format_summary(analyses: Sequence[BagAnalysis]) -> str:
    """The terminal summary: per feeder what the bag is, its headline figures and tables (the
    report's, from :mod:`feeder_ros.bag.presentation`), then a comparison of several."""
    parts: list[str] = []
    for section in presentation.sections(analyses, diagnostics_limit=_TERMINAL_DIAGNOSTICS):
        if section.error:
            parts.append(f"{section.title}: {section.error}")
            continue
        parts += section.lines
        parts += [f"  {alert}" for alert in section.alerts]
        if section.headline:
            width = max(len(f.label) for f in section.headline)
            parts += [f"  {f.label + ':':<{width + 1}} {f.value}" for f in section.headline]
        for table in section.tables:
            parts += [f"  {table.title}:", presentation.text_table(table, indent="    ")]
        parts += [f"  problem: {problem}" for problem in section.problems]
    if len(analyses) > 1:
        parts += ["comparison:", presentation.text_table(presentation.comparison_table(analyses))]
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


_STYLE = """
body{font-family:system-ui,sans-serif;max-width:1240px;margin:0 auto;padding:0 16px;color:#222}
h1{font-size:1.6em}h2{margin-top:2em;border-bottom:2px solid #ccc;overflow-wrap:anywhere}
p.bag{color:#555;margin:.2em 0;overflow-wrap:anywhere}.alert{color:#b00;font-weight:bold}
dl.headline{display:flex;flex-wrap:wrap;gap:10px;margin:1em 0}
dl.headline div{border:1px solid #ccc;border-radius:6px;padding:8px 14px;min-width:140px}
dl.headline dt{font-size:.85em;color:#555}dl.headline dd{margin:0;font-size:1.35em}
table{border-collapse:collapse;max-width:100%;margin:.5em 0 1.5em;font-size:.9em}
th,td{border:1px solid #ccc;padding:3px 6px;vertical-align:top}th{background:#f3f3f3}
.num{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}th.num{white-space:normal}
.text{text-align:left;white-space:nowrap}.wrap{text-align:left;overflow-wrap:anywhere}img{max-width:100%;height:auto}
"""


def _html_section(section: Section, images: dict[str, bytes]) -> list[str]:
    out = [f"<section><h2>{html.escape(section.title)}</h2>"]
    if section.error:
        return [*out, f"<p class='alert'>{html.escape(section.error)}</p></section>"]
    out += [f"<p class='bag'>{html.escape(line.strip())}</p>" for line in section.lines]
    out += [f"<p class='alert'>{html.escape(alert)}</p>" for alert in section.alerts]
    if section.headline:
        out.append("<dl class='headline'>")
        out += [
            f"<div data-key='{f.key}'><dt>{html.escape(f.label)}</dt>"
            f"<dd>{html.escape(f.value)}</dd></div>"
            for f in section.headline
        ]
        out.append("</dl>")

    def image(kind: str, title: str) -> None:
        if kind in images:
            encoded = base64.b64encode(images[kind]).decode()
            out.extend(
                [f"<h3>{title}</h3>", f"<img alt='{kind}' src='data:image/png;base64,{encoded}'>"]
            )

    image("timeline", "Part speed and drive over time")
    for table in section.tables:
        out += [f"<h3>{html.escape(table.title)}</h3>", presentation.html_table(table)]
    image("segments", "Speed and slip per segment")
    image("frequency_response", "Frequency response")
    if section.problems:
        out.append("<h3>Problems</h3><ul>")
        out += [f"<li>{html.escape(p)}</li>" for p in section.problems]
        out.append("</ul>")
    return [*out, "</section>"]


def _csv_files(a: BagAnalysis) -> dict[str, bytes]:
    """One feeder's machine-readable tables (full precision, SI-named columns)."""
    files = {"segments.csv": _csv(segment_rows(a))}
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
        files["frequency_response.csv"] = _csv(fr)
    if a.diagnostics:
        diag = [
            {"t_s": d.t_s, "name": d.name, "level": d.level_name, "message": d.message}
            for d in a.diagnostics
        ]
        files["diagnostics.csv"] = _csv(diag)
    return files


def write_outputs(analyses: Sequence[BagAnalysis], directory: Path) -> list[Path]:
    """Write CSV tables, ``analysis.json``, PNG plots and ``report.html`` into ``directory``."""
    directory.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []

    def put(name: str, data: bytes) -> None:
        path = directory / name
        atomic_bytes(path, data)
        written.append(path)

    body: list[str] = []
    shown = presentation.sections(analyses)
    for stem, a, section in zip(_stems(analyses), analyses, shown, strict=True):
        images: dict[str, bytes] = {}
        if a.ok:
            for name, data in _csv_files(a).items():
                put(f"{stem}_{name}", data)
            images = report_plots.plots(a)
            for kind, png in images.items():
                put(f"{stem}_{kind}.png", png)
        body += _html_section(section, images)
    comparison = comparison_rows(analyses)
    put("comparison.csv", _csv(comparison))
    if len(analyses) > 1:
        table = presentation.comparison_table(analyses)
        body += ["<section><h2>Comparison</h2>", presentation.html_table(table), "</section>"]
    document = {"bags": [_json_safe(a.as_dict()) for a in analyses]}
    put("analysis.json", (json.dumps(document, indent=1) + "\n").encode())
    page = (
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
        "<meta name='viewport' content='width=device-width, initial-scale=1'>"
        f"<title>feeder analyze</title><style>{_STYLE}</style></head><body>"
        "<h1>Feeder run report</h1>" + "\n".join(body) + "</body></html>\n"
    )
    put("report.html", page.encode())
    return written
