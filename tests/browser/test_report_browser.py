"""`rrbc report`'s HTML opened in Chromium (issue 40, item 4): it loads with no request beyond the file itself,
every figure is drawn (decoded, with a size) and every check id is listed."""

import json
import subprocess
import sys
from pathlib import Path

from tests.paths import ROOT

RRBC = str(Path(sys.executable).with_name("rrbc"))
EXAMPLE = ROOT / "rrbc_core" / "data" / "example_measurements.csv"


def test_the_report_opens_offline_with_its_figures_drawn_and_every_check_listed(browser_context, tmp_path):
    out = tmp_path / "report.html"
    r = subprocess.run(
        [RRBC, "report", str(EXAMPLE), "--tolerance", "0.3", "--out", str(out), "--json"],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    acc = json.loads(r.stdout)
    page = browser_context.new_page()
    requests: list[str] = []
    page.on("request", lambda req: requests.append(req.url))
    page.goto(out.as_uri())
    page.wait_for_function("Array.from(document.images).every(i => i.complete && i.naturalWidth > 0)")
    sizes = page.evaluate("Array.from(document.images).map(i => [i.naturalWidth, i.naturalHeight])")
    assert len(sizes) == 2 and all(w > 200 and h > 100 for w, h in sizes), sizes
    assert [u for u in requests if not u.startswith("data:")] == [out.as_uri()]
    body = page.inner_text("body")
    assert "FAIL" in body or "PASS" in body or "UNDECIDED" in body
    for p in acc["points"]:
        if p["role"] == "check":
            assert p["id"] in body
    page.close()
