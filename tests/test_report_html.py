"""report.html in a real headless browser (Debian's chromium): it loads with no console message
and shows every table and every figure. CI installs chromium (.ci/install-chromium) and sets
CDNF_TI_REQUIRE_CHROMIUM=1 so the test cannot be skipped there."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from cdnf_ti.experiments.dataset import run_dataset
from cdnf_ti.experiments.paramsweep import run_param_sweep
from cdnf_ti.experiments.synthetic import make_synthetic_dataset

#: Appended to a copy of the page: after load, record in <body> how many tables are laid out with a
#: visible box and how many images decoded (the page itself has no script).
PROBE = """<script>
window.addEventListener("load", function () {
  var tables = Array.from(document.querySelectorAll("table"));
  var shown = tables.filter(function (t) {
    var r = t.getBoundingClientRect(), s = getComputedStyle(t);
    return r.width > 0 && r.height > 0 && s.display !== "none" && s.visibility !== "hidden";
  });
  var imgs = Array.from(document.querySelectorAll("img"));
  var ok = imgs.filter(function (i) { return i.complete && i.naturalWidth > 0; });
  document.body.setAttribute("data-tables", tables.length);
  document.body.setAttribute("data-tables-shown", shown.length);
  document.body.setAttribute("data-images", imgs.length);
  document.body.setAttribute("data-images-ok", ok.length);
});
</script>"""


def _chromium() -> str:
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        if os.environ.get("CDNF_TI_REQUIRE_CHROMIUM"):
            pytest.fail("chromium is required here (run .ci/install-chromium)")
        pytest.skip("chromium is not installed (.ci/install-chromium installs it)")
    return exe


def _load(page: Path, tmp_path: Path) -> tuple[str, list[str]]:
    """Load ``page`` (with the probe) in headless chromium; returns (DOM after load, console lines)."""
    probe = tmp_path / f"probe_{page.name}"
    probe.write_text(page.read_text(encoding="utf-8").replace("</body>", PROBE + "</body>"), encoding="utf-8")
    profile = tmp_path / "chromium-profile"
    profile.mkdir(exist_ok=True)
    p = subprocess.run([_chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                        "--disable-background-networking", "--disable-component-update", "--disable-sync",
                        f"--user-data-dir={profile}", "--enable-logging=stderr", "--v=0",
                        "--dump-dom", probe.as_uri()], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr[-2000:]
    console = [ln for ln in p.stderr.splitlines() if ":CONSOLE" in ln]
    return p.stdout, console


def _attr(dom: str, name: str) -> int:
    m = re.search(rf'{name}="(\d+)"', dom)
    assert m, f"probe attribute {name} missing: the page did not finish loading"
    return int(m.group(1))


def _check(page: Path, tmp_path: Path, min_tables: int, min_images: int) -> str:
    html = page.read_text(encoding="utf-8")
    assert "http://" not in html and "https://" not in html and "src=\"data:image/png;base64," in html
    dom, console = _load(page, tmp_path)
    assert console == []
    n = _attr(dom, "data-tables")
    assert n == html.count("<table") and n >= min_tables
    assert _attr(dom, "data-tables-shown") == n
    k = _attr(dom, "data-images")
    assert k >= min_images and _attr(dom, "data-images-ok") == k
    return dom


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    ds = tmp_path_factory.mktemp("ds")
    make_synthetic_dataset(ds, size=32, clips=("dark_looming", "light_translating", "dark_receding"))
    return ds


def test_dataset_report_loads_without_console_messages_and_shows_every_table(dataset, tmp_path):
    run = run_dataset(dataset, None, tmp_path / "out", models=["cdnf", "lgmd2"], rain="both", workers=0,
                      progress=False)
    dom = _check(run.out / "report.html", tmp_path, min_tables=5, min_images=3 + 3)
    for words in ("ROC AUC", "CV accuracy", "never alerts (baseline)", "IN-SAMPLE", "dark_looming"):
        assert words in dom


def test_sweep_report_loads_without_console_messages_and_shows_every_table(dataset, tmp_path):
    run_param_sweep(dataset, None, tmp_path / "sw", "cdnf", ["h=0.15,0.25"], workers=0, progress=False)
    dom = _check(tmp_path / "sw" / "report.html", tmp_path, min_tables=1, min_images=1)
    assert "in-sample" in dom and "CV accuracy" in dom


def test_a_console_error_is_caught(tmp_path):
    bad = tmp_path / "bad.html"
    bad.write_text("<!DOCTYPE html><html><body><table><tr><td>x</td></tr></table>"
                   "<script>console.error('broken')</script></body></html>")
    _dom, console = _load(bad, tmp_path)
    assert any("broken" in ln for ln in console)


def test_markdown_tables_become_html_tables_without_the_rule_row():
    from cdnf_ti.experiments.htmlreport import Page, add_markdown

    page = Page("t")
    add_markdown(page, "# T\n\n## Head\n\n- a `b`\n\n| x | y |\n|---|---|\n| 1 | 2 |\n| 3 | 4 |\n\ntext\n")
    html = page.render()
    assert html.count("<table") == 1 and html.count("<tr>") == 3 and "---" not in html
    assert "<h2>Head</h2>" in html and "<li>a b</li>" in html and "<p>text</p>" in html
