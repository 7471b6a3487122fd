"""A real browser for report tests: Debian's ``chromium``, headless, at a given window width.

:func:`layout` opens a page with a probe script appended (the page itself is not changed) that
measures, after the page loaded, every element's right edge against the window, and reads the
headline figures (``dl.headline``) and the images as rendered; the browser's DOM dump carries the
result back. ``make test`` installs chromium when it is missing (``make browser``).
"""

from __future__ import annotations

import html
import json
import re
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest

_PROBE = """<script>
window.addEventListener('load', () => {
  const width = document.documentElement.clientWidth;
  const over = [];
  for (const el of document.querySelectorAll('body *')) {
    const box = el.getBoundingClientRect();
    if (box.right > width + 0.5) {
      over.push(`${el.tagName}.${el.className}: right edge ${box.right.toFixed(0)} px: `
                + (el.textContent || '').slice(0, 60));
    }
  }
  const headline = {};
  for (const fact of document.querySelectorAll('dl.headline div')) {
    headline[fact.dataset.key] = fact.querySelector('dd').textContent;
  }
  const result = {
    width: width,
    scroll_width: document.documentElement.scrollWidth,
    over: over,
    headline: headline,
    images: [...document.images].map(i => [i.complete, i.naturalWidth, i.width]),
    tables: [...document.querySelectorAll('table')].map(t => t.dataset.table),
  };
  const out = document.createElement('pre');
  out.id = 'layout-probe';
  out.textContent = JSON.stringify(result);
  document.body.appendChild(out);
});
</script>"""


def chromium() -> str:
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if found is None:
        pytest.fail("no chromium: `make browser` installs Debian's (make test runs it)")
    return found


def layout(page: Path, width: int = 1280, height: int = 1000) -> dict[str, Any]:
    """What the browser rendered of ``page`` in a window ``width`` px wide (see the module)."""
    probe = page.with_name(f"{page.stem}.probe.html")
    probe.write_text(page.read_text().replace("</body>", _PROBE + "</body>"))
    try:
        result = subprocess.run(
            [chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
             f"--window-size={width},{height}", "--virtual-time-budget=10000", "--dump-dom",
             probe.as_uri()],
            capture_output=True, text=True, timeout=180,
        )  # fmt: skip
    finally:
        probe.unlink()
    found = re.search(r'<pre id="layout-probe">(.*?)</pre>', result.stdout, re.S)
    assert found, f"no layout from chromium (exit {result.returncode}): {result.stderr[-2000:]}"
    return dict(json.loads(html.unescape(found.group(1))))
