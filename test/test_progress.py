"""The shared progress bar: redraws on percentage changes only, one line per item."""

from __future__ import annotations

import io

from feeder_ros.cli.progress import ProgressBar


def test_bar_draws_each_percentage_once_and_ends_the_line() -> None:
    out = io.StringIO()
    bar = ProgressBar("sweep", 200, True, stream=out)
    for done in (0, 1, float("nan"), 2, 100, 100.4, 200, 250):  # nan: not drawn, no error
        bar.update(done)
    bar.close()
    frames = out.getvalue().split("\r")[1:]
    assert [f.rstrip("\n").split()[-1] for f in frames] == ["0%", "1%", "50%", "100%"]
    assert frames[2].startswith("sweep [" + "#" * 12 + " " * 13 + "]")
    assert out.getvalue().endswith("100%\n")


def test_relabel_starts_a_new_line_and_disabled_bar_writes_nothing() -> None:
    out = io.StringIO()
    bar = ProgressBar("a.mcap", 1.0, True, stream=out)
    bar.update(1.0)
    bar.relabel("b.mcap")
    bar.update(0.5)
    bar.close()
    assert (
        out.getvalue()
        == "\ra.mcap [" + "#" * 25 + "] 100%\n\rb.mcap [" + "#" * 12 + " " * 13 + "]  50%\n"
    )
    quiet = io.StringIO()
    off = ProgressBar("x", 1.0, False, stream=quiet)
    off.update(0.5)
    off.close()
    assert quiet.getvalue() == ""


def test_after_a_second_the_line_shows_elapsed_time_rate_and_eta() -> None:
    now = [100.0]
    out = io.StringIO()
    bar = ProgressBar("simulating", 600.0, True, stream=out, unit="s", clock=lambda: now[0])
    bar.update(3.0)  # 0.5 s in: the bar alone
    now[0] = 130.0
    bar.update(150.0)  # 30 s for a quarter: 5 s/s, 90 s left
    now[0] = 3700.0
    bar.update(599.0)
    bar.update(600.0)
    bar.relabel("next", 10.0)  # a new item starts its own clock
    bar.update(6.0)
    bar.close()
    frames = [f.rstrip("\n") for f in out.getvalue().split("\r")[1:]]
    assert frames[0] == "simulating [" + " " * 25 + "]   0%"
    assert frames[1] == "simulating [" + "#" * 6 + " " * 19 + "]  25%  0:30, 5 s/s, ETA 1:30"
    assert frames[2].endswith("  99%  1:00:00, 0.166 s/s, ETA 0:06")
    assert frames[3] == "simulating [" + "#" * 25 + "] 100%  1:00:00, 0.167 s/s" + " " * 10  # pads
    assert frames[4] == "next [" + "#" * 15 + " " * 10 + "]  60%"
