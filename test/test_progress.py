"""The shared progress bar (tqdm underneath): what its line shows, one line per item, silence
when disabled."""

from __future__ import annotations

import io
import re
import time

from feeder_ros.cli.progress import ProgressBar


def frames(out: io.StringIO) -> list[str]:
    """Every state the bar drew, in order (tqdm rewrites its line after a carriage return)."""
    return [f.strip() for f in re.split(r"[\r\n]", out.getvalue()) if f.strip()]


def test_a_bar_with_a_unit_shows_done_of_total_elapsed_eta_and_rate() -> None:
    out = io.StringIO()
    bar = ProgressBar("design search", 200, True, stream=out, unit="designs")
    bar.update(0)
    time.sleep(0.3)
    bar.update(50)
    time.sleep(0.3)
    bar.update(float("nan"))  # ignored, no error
    bar.update(250)  # clipped to the total
    bar.close()
    drawn = frames(out)
    assert drawn[0].startswith("design search   0%|")
    quarter = next(f for f in drawn if f.startswith("design search  25%|"))
    assert re.search(r"\| 50/200 designs \[00:00<00:0\d, +[0-9.]+ designs/s\]$", quarter), quarter
    assert re.search(r"^design search 100%\|.*\| 200/200 designs \[00:00<00:00", drawn[-1])
    assert out.getvalue().endswith("\n")


def test_a_fraction_bar_shows_times_only_and_relabel_starts_a_new_line() -> None:
    out = io.StringIO()
    bar = ProgressBar("a.mcap", 1.0, True, stream=out)
    bar.update(1.0)
    bar.relabel("b.mcap")
    bar.update(0.5)
    bar.close()
    lines = out.getvalue().split("\n")
    assert lines[-1] == ""
    assert re.search(r"a\.mcap 100%\|.*\| \[\d\d:\d\d<\d\d:\d\d\]$", lines[0].split("\r")[-1])
    assert re.search(r"b\.mcap  50%\|.*\| \[\d\d:\d\d<", lines[1].split("\r")[-1])
    assert len(lines) == 3  # one line per item


def test_a_disabled_bar_writes_nothing() -> None:
    quiet = io.StringIO()
    off = ProgressBar("x", 1.0, False, stream=quiet)
    off.update(0.5)
    off.relabel("y")
    off.update(1.0)
    off.close()
    assert quiet.getvalue() == ""
