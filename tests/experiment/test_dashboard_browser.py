"""The sweep dashboard in a real browser (headless Debian Chromium through Playwright): the
static page loads with no console error and requests nothing but itself, the AP plot has one
mean series per condition, the runs table sorts, a screenshot is taken; the served page shows a
run appended to runs.parquet without a reload; the primary endpoint and the pre-trainings'
sections render, and hide where an old sweep has neither; clicking a run opens its own view
with its numbers from runs.parquet (offline, and served at /run/<id>); the gap report's
figures are drawn from gap.json; the comparison page of two sweeps renders its figures.

Needs ``/usr/bin/chromium`` (``make setup`` installs Debian's ``chromium``; Playwright's own
browser downloads are not used). Skipped only on a machine without apt.
"""

from __future__ import annotations

import json
import shutil
import struct
from pathlib import Path

import pytest

from sim2radar.experiment.dashboard import (
    load_sweep,
    serve_dashboard,
    write_comparison,
    write_dashboard,
)
from tests.experiment.test_dashboard import (
    append_run,
    edit_sweep_json,
    make_sweep,
    pretrain_row,
    run_row,
    write_pretrainings,
)
from tests.experiment.test_dashboard_gap import _gap_report_into
from tests.experiment.test_dashboard_runs import _with_pretrainings

CHROMIUM = Path("/usr/bin/chromium")
#: flags for a sandbox-less container; without the background-networking ones Chromium's own
#: connections (component updates, ...) would show up as refused requests
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]
TIMEOUT_MS = 15_000

if not CHROMIUM.exists():
    # a skip only where apt cannot install it; elsewhere a missing browser is a setup failure
    if shutil.which("apt-get") is None:
        pytest.skip("no apt on this machine to install Debian's chromium: browser tests skipped",
                    allow_module_level=True)
    pytest.fail(f"{CHROMIUM} not found: run `make setup` (or `sudo apt-get install chromium`)",
                pytrace=False)
try:
    from playwright.sync_api import sync_playwright
except ImportError:
    pytest.fail("the playwright package is missing: pip install -e '.[dev]' (or `make setup`)",
                pytrace=False)


@pytest.fixture(scope="module")
def browser():
    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS, headless=True)
        try:
            yield b
        finally:
            b.close()


@pytest.fixture
def page(browser):
    """A page that records every request, console error and uncaught exception."""
    ctx = browser.new_context(viewport={"width": 1280, "height": 900})
    pg = ctx.new_page()
    pg.requests, pg.errors = [], []
    pg.on("request", lambda r: pg.requests.append(r.url))
    pg.on("console", lambda m: pg.errors.append(m.text) if m.type == "error" else None)
    pg.on("pageerror", lambda e: pg.errors.append(str(e)))
    pg.set_default_timeout(TIMEOUT_MS)
    yield pg
    ctx.close()


_ROLES_JS = """(role) => document.getElementById('plot-ap').data
    .filter(t => t.meta && t.meta.role === role).map(t => t.meta.condition)"""


def test_static_page_is_offline_plots_every_condition_and_sorts(tmp_path, page):
    sweep = make_sweep(tmp_path / "t")
    html = write_dashboard(sweep, tmp_path / "dash.html")
    page.goto(html.as_uri())
    page.wait_for_selector("#plot-ap .main-svg")
    page.wait_for_selector("#plot-curves .main-svg")
    assert page.evaluate(_ROLES_JS, "mean") == ["baseline", "sim-pretrain"]
    assert page.evaluate(_ROLES_JS, "trials") == ["baseline", "sim-pretrain"]
    # the rendered SVG draws the two mean lines (one path each), not just the data
    assert page.locator("#plot-ap .scatterlayer .trace .js-line").count() == 2
    assert page.locator("#banner.proxy").inner_text().startswith("PROXY real domain")
    assert page.locator("#run-count").inner_text() == "18"
    # the fixture's gap.json is an older report's: azimuth, range and intensity are drawn
    # from its numbers, the overlay (no numbers) is its PNG, and the page says why
    page.wait_for_selector("#gap-plot-intensity .main-svg")
    assert page.locator("#gap .gap-plot .main-svg").count() >= 3
    assert page.locator(".gap-figs img").count() == 1
    assert "holds no numbers for them" in page.locator("#gap-image-note").inner_text()
    assert page.evaluate("Array.from(document.images).every(i => i.complete && "
                         "i.naturalWidth > 0)")

    # sort by the headline AP: ascending, then descending on a second click; failed run last
    heading = page.locator("#runs-table th", has_text="3D AP R40 @0.3")
    col = int(heading.get_attribute("data-col"))
    cells_js = f"""() => Array.from(document.querySelectorAll('#runs-table tbody tr'))
        .map(r => r.children[{col}].textContent)"""
    heading.click()
    asc = page.evaluate(cells_js)
    assert page.locator("#runs-table th[aria-sort=ascending]").count() == 1
    values = [float(v) for v in asc if v != "—"]
    assert values == sorted(values) and asc[-1] == "—" and len(asc) == 18
    heading.click()
    desc = page.evaluate(cells_js)
    assert [float(v) for v in desc if v != "—"] == sorted(values, reverse=True)
    assert desc[-1] == "—"

    shot = page.screenshot(path=str(tmp_path / "dashboard.png"), full_page=True)
    width, height = struct.unpack(">II", shot[16:24])       # PNG IHDR
    assert shot.startswith(b"\x89PNG\r\n\x1a\n") and len(shot) > 50_000
    assert width == 1280 and height > 2000
    assert page.errors == []
    assert page.requests == [html.as_uri()]                 # nothing but the file itself


def test_served_page_shows_a_new_run_without_reload(tmp_path, page):
    sweep = make_sweep(tmp_path / "s", ran=("baseline",), failed=())
    with serve_dashboard(sweep, poll_s=0.5) as server:
        page.goto(server.url)
        page.wait_for_selector("#plot-ap .main-svg")
        assert page.locator("#run-count").inner_text() == "9"
        assert page.evaluate(_ROLES_JS, "mean") == ["baseline", "sim-pretrain"]
        page.evaluate("window.__notReloaded = true")
        renders = page.evaluate("window.dashboard.renders")

        n = append_run(sweep, run_row("sim-pretrain", 0.1, 0))
        # a function, not an expression string: the page's CSP refuses eval (as it should)
        page.wait_for_function("(n) => document.getElementById('run-count').textContent "
                               "=== String(n)", arg=n)
        assert page.locator("#runs-table tbody tr").count() == n
        assert page.evaluate("window.__notReloaded === true")        # updated in place
        assert page.evaluate("window.dashboard.renders") > renders
        # the new run reached the plot: sim-pretrain's trial points now hold one value
        assert page.evaluate("""() => document.getElementById('plot-ap').data
            .find(t => t.meta.role === 'trials' && t.meta.condition === 'sim-pretrain')
            .y.length""") == 1
        assert page.errors == []
        origin = server.url.rstrip("/")
        assert {u.split("?")[0] for u in page.requests} <= {server.url, origin + "/data.json"}


def test_runs_filter_group_and_download_offline(tmp_path, page):
    """Filter the runs by condition and fraction, group them by trial, and download the rows
    shown as CSV and JSON: the files hold exactly those runs with their folders, and the page
    still requests nothing but itself. The summary states what the sweep could detect."""
    import csv
    import io

    sweep = make_sweep(tmp_path / "t")
    html = write_dashboard(sweep, tmp_path / "dash.html")
    page.goto(html.as_uri())
    page.wait_for_selector("#plot-delta .main-svg")
    summary = page.locator("#power-summary").inner_text()
    assert "could detect gains of ≥" in summary and "paper's effects" in summary
    assert page.locator("#summary th", has_text="MDE").count() == 1
    assert page.locator("#summary th", has_text="P(improved)").count() == 1

    rows = page.locator("#runs-table tbody tr.run")
    assert rows.count() == 18
    page.select_option("#filter-condition", "sim-pretrain")
    assert rows.count() == 9
    page.select_option("#filter-fraction", "0.5")
    assert rows.count() == 3 and page.locator("#runs-table tbody tr.failed").count() == 1
    assert page.locator("#runs-shown").inner_text() == "3 of 18 runs shown"
    # the learning curves follow the filters: only sim-pretrain at 50 % stays visible
    shown = page.evaluate("""() => document.getElementById('plot-curves').data
        .filter(t => t.meta && t.meta.condition !== undefined && t.visible !== false)
        .map(t => [t.meta.condition, t.meta.fraction])""")
    assert shown and all(c == "sim-pretrain" and f == 0.5 for c, f in shown)
    # condition shown by its label, each run with its folder
    texts = page.evaluate("""() => Array.from(document.querySelectorAll(
        '#runs-table tbody tr.run')).map(r => r.textContent)""")
    assert all("Sim Pretrain" in t for t in texts)
    assert any("runs/sim-pretrain-0.5-0" in t for t in texts)

    with page.expect_download() as info:
        page.click("#download-csv")
    dl = info.value
    assert dl.suggested_filename == "sweep-t-runs.csv"
    table = list(csv.DictReader(io.StringIO(open(dl.path(), encoding="utf-8").read())))
    assert len(table) == 3
    assert {r["condition"] for r in table} == {"sim-pretrain"}
    assert {r["fraction"] for r in table} == {"0.5"}
    assert sorted(r["run_folder"] for r in table if r["status"] == "ok") == [
        "runs/sim-pretrain-0.5-0", "runs/sim-pretrain-0.5-1"]
    ok = next(r for r in table if r["trial"] == "1")
    assert float(ok["ap_3d_r40_iou03"]) == pytest.approx(20 + 40 * 0.5 + 1 + 3.5)
    failed = next(r for r in table if r["status"] == "failed")
    assert failed["ap_3d_r40_iou03"] == "" and "</script>" in failed["error"]

    page.select_option("#filter-fraction", "")          # all fractions again
    page.select_option("#group-by", "trial")
    groups = page.locator("#runs-table tbody tr.group")
    assert groups.count() == 3 and rows.count() == 9
    assert groups.first.inner_text().startswith("trial 0 · 3 run(s) · mean 3D AP R40 @0.3")
    trials = page.evaluate("""() => Array.from(document.querySelectorAll(
        '#runs-table tbody tr.run')).map(r => r.children[2].textContent)""")
    assert trials == sorted(trials)                     # grouped rows are contiguous
    with page.expect_download() as info:
        page.click("#download-json")
    doc = json.loads(open(info.value.path(), encoding="utf-8").read())
    assert len(doc) == 9 and {r["condition"] for r in doc} == {"sim-pretrain"}
    assert [r["trial"] for r in doc] == sorted(r["trial"] for r in doc)
    assert all(r["run_folder"].startswith("runs/sim-pretrain-") for r in doc)

    # sorting still works inside the filtered view
    heading = page.locator("#runs-table th", has_text="3D AP R40 @0.3")
    page.select_option("#group-by", "")
    heading.click()
    col = int(heading.get_attribute("data-col"))
    vals = page.evaluate(f"""() => Array.from(document.querySelectorAll(
        '#runs-table tbody tr.run')).map(r => r.children[{col}].textContent)""")
    nums = [float(v) for v in vals if v != "—"]
    assert nums == sorted(nums) and len(vals) == 9
    assert page.errors == []
    assert page.requests == [html.as_uri()]             # downloads built in the page


def test_primary_endpoint_and_pretrainings_render(tmp_path, page):
    """A sweep with pre-trainings and a threshold: the primary sentence and table, the
    pre-training summary, the check and loss plots (drawn) and every pre-training in the
    details; an old sweep without them hides the primary section and says so for the
    pre-trainings."""
    sweep = make_sweep(tmp_path / "t")
    edit_sweep_json(sweep, learnability_thresholds={"sim-pretrain": 35.0})
    write_pretrainings(sweep, [pretrain_row(0, heldout=30.0), pretrain_row(1, heldout=40.0),
                               pretrain_row(2, status="failed", loss=(3.0,),
                                            error="diverged </script><b>x</b>")])
    html = write_dashboard(sweep, tmp_path / "dash.html")
    page.goto(html.as_uri())
    page.wait_for_selector("#plot-pretrain-check .main-svg")
    page.wait_for_selector("#plot-pretrain-loss .main-svg")
    assert page.locator("#primary-section").is_visible()
    assert page.locator("#primary-sentence").inner_text().startswith(
        "Primary endpoint (pre-registered): Sim Pretrain vs Baseline pooled over 10 %")
    assert page.locator("#primary-table td", has_text="primary").count() == 1
    assert page.locator("#summary th", has_text="simultaneous 95 % CI (Holm family)").count() == 1
    assert "Holm-adjusted" in page.locator("#summary-note").inner_text()
    assert page.locator("#pretrain-empty").is_hidden()
    assert "35.0 (met 1/2)" in page.locator("#pretrain-summary").inner_text()
    assert page.evaluate("""() => document.getElementById('plot-pretrain-loss').data
        .filter(t => t.meta.role === 'pretrain_loss').length""") == 2
    assert page.evaluate("""() => document.getElementById('plot-pretrain-check').data
        .filter(t => t.meta.measure === 'threshold').length""") == 1
    page.click("#pretrain-details-summary")
    assert page.locator("#pretrain-rows tbody tr").count() == 3
    assert "diverged </script><b>x</b>" in page.locator("#pretrain-rows").inner_text()
    assert page.errors == [] and page.requests == [html.as_uri()]

    old = make_sweep(tmp_path / "old")
    doc = {k: v for k, v in load_sweep(old).stats.items()
           if k not in ("pooled", "primary", "pretrainings")}
    (old / "stats.json").write_text(json.dumps(doc))
    html = write_dashboard(old, tmp_path / "old.html")
    page.goto(html.as_uri())
    page.wait_for_selector("#plot-delta .main-svg")
    assert page.locator("#primary-section").is_hidden()
    assert page.locator("#pretrain-empty").inner_text() == "No pre-training recorded."
    assert page.locator("#plot-pretrain-check").is_hidden()
    assert page.errors == []


_RUN_JS = """() => ({
    settings: Object.fromEntries(Array.from(document.querySelectorAll(
        '#run-settings tbody tr')).map(r => [r.children[0].textContent,
                                             r.children[1].textContent])),
    aps: Array.from(document.querySelectorAll('#run-aps tbody tr')).map(r =>
        [r.children[0].textContent, r.children[1].textContent]),
    traces: Object.fromEntries(document.getElementById('plot-run').data.map(t =>
        [t.meta.role, {x: t.x, y: t.y}])),
    pretrain: document.getElementById('run-pretrain').textContent,
    folder: document.getElementById('run-folder').textContent})"""


def test_clicking_a_run_opens_its_view_with_its_numbers(tmp_path, page):
    """Click a run's row: its view shows that run's settings, final APs and learning curve as
    runs.parquet holds them, and its pre-training's check; the address names the run (a
    link opens it), and closing the view hides it. Offline: nothing is requested."""
    import pyarrow.parquet as pq

    from sim2radar.experiment.dashboard.labels import metric_label

    sweep = _with_pretrainings(tmp_path / "t")
    html = write_dashboard(sweep, tmp_path / "dash.html")
    runs = {r["run_key"]: r for r in pq.read_table(sweep / "runs.parquet").to_pylist()}
    page.goto(html.as_uri())
    page.wait_for_selector("#plot-ap .main-svg")
    assert page.locator("#run-section").is_hidden()
    for cond, fraction, trial in (("sim-pretrain", 0.5, 1), ("baseline", 0.1, 2)):
        key = f"{cond}-{fraction:g}-{trial}-" + "0" * 40
        page.locator(f"#runs-table tr[data-run='{key}'] td").first.click()
        page.wait_for_function("(k) => !document.getElementById('run-section').hidden && "
                               "document.getElementById('run-id').textContent === k", arg=key)
        page.wait_for_selector("#plot-run .main-svg")
        assert page.evaluate("location.hash") == f"#run={key}"
        assert page.locator(f"#runs-table tr.selected[data-run='{key}']").count() == 1
        row, shown = runs[key], page.evaluate(_RUN_JS)
        assert shown["settings"]["seed"] == str(row["seed"])
        assert shown["settings"]["trial"] == str(row["trial"])
        assert shown["settings"]["epochs"] == str(row["epochs"])
        assert shown["settings"]["run key"] == key
        # every final AP, the sweep's metric first, as runs.parquet holds it
        assert shown["aps"][0][0].startswith(metric_label("ap_3d_r40_iou03"))
        for label, value in shown["aps"]:
            metric = next(m for m in row if m.startswith("ap_")
                          and label.startswith(metric_label(m)))
            assert float(value) == pytest.approx(row[metric], abs=0.005), label
        assert shown["traces"]["run_loss"]["y"] == pytest.approx(row["history_loss"])
        assert shown["traces"]["run_loss"]["x"] == row["history_epoch"]
        assert shown["traces"]["run_val_ap"]["y"] == pytest.approx(row["history_val_ap"])
        assert shown["folder"] == f"runs/{cond}-{fraction:g}-{trial}"
    assert shown["pretrain"] == "" and "run_pretrain_loss" not in shown["traces"]
    assert "from scratch" in page.locator("#run-pretrain-note").inner_text()

    # a link to a run opens it; the pre-training it loaded is shown with its check
    key = "sim-pretrain-0.1-1-" + "0" * 40
    page.goto(html.as_uri() + f"#run={key}")
    page.wait_for_function("(k) => document.getElementById('run-id').textContent === k",
                           arg=key)
    shown = page.evaluate(_RUN_JS)
    assert "pretrain-sim-t1" in shown["pretrain"] and "35 — met" in shown["pretrain"]
    assert shown["traces"]["run_pretrain_loss"]["y"] == [3.0, 2.0, 2.0]
    page.click("#run-close")
    assert page.locator("#run-section").is_hidden() and page.evaluate("location.hash") == ""
    assert page.errors == []
    assert page.requests == [html.as_uri()] * len(page.requests)   # the file only


def test_served_run_address_opens_its_view_and_stays_live(tmp_path, page):
    sweep = make_sweep(tmp_path / "s", ran=("baseline",), failed=())
    key = run_row("baseline", 0.5, 2)["run_key"]
    with serve_dashboard(sweep, poll_s=0.5) as server:
        page.goto(server.url + f"run/{key}")
        page.wait_for_selector("#plot-run .main-svg")
        assert page.locator("#run-title").inner_text() == "Run: Baseline · 50 % real · trial 2"
        assert page.locator("#run-settings").inner_text().count("1002") == 1     # its seed
        # polling from /run/<id> reads the root's data.json: a new run still arrives
        n = append_run(sweep, run_row("sim-pretrain", 0.1, 0))
        page.wait_for_function("(n) => document.getElementById('run-count').textContent "
                               "=== String(n)", arg=n)
        assert page.locator("#run-section").is_visible()
        assert page.errors == []
        origin = server.url.rstrip("/")
        assert {u.split("?")[0] for u in page.requests} <= {server.url + f"run/{key}",
                                                            origin + "/data.json"}


def test_gap_figures_are_drawn_from_the_reports_numbers(tmp_path, page):
    sweep = make_sweep(tmp_path / "g")
    _gap_report_into(sweep)
    html = write_dashboard(sweep, tmp_path / "dash.html")
    page.goto(html.as_uri())
    for name in ("overlay", "points", "azimuth", "range", "intensity", "artefacts",
                 "fidelity"):
        page.wait_for_selector(f"#gap-plot-{name} .main-svg")
    assert page.locator(".gap-figs img").count() == 0
    # the overlay draws the frame's points: 4 sim and 4 real in each view
    assert page.locator("#gap-plot-overlay .scatterlayer .trace .point").count() >= 16
    assert page.errors == [] and page.requests == [html.as_uri()]


def test_comparison_page_renders_its_figures_offline(tmp_path, page):
    a = make_sweep(tmp_path / "a")
    b = make_sweep(tmp_path / "b", conditions=("baseline", "sim-pretrain", "sim-gt-pretrain"),
                   fractions=(0.1, 0.25, 0.5), failed=())
    html = write_comparison(a, b, tmp_path / "cmp.html")
    page.goto(html.as_uri())
    page.wait_for_selector("#plot-ap .main-svg")
    page.wait_for_selector("#plot-delta .main-svg")
    # 2 shared conditions x 2 sweeps drawn as lines; the difference of the Δs per condition
    assert page.locator("#plot-ap .scatterlayer .trace .js-line").count() == 4
    assert page.evaluate("""() => document.getElementById('plot-delta').data
        .filter(t => t.meta.role === 'delta-diff').length""") == 1
    assert page.locator("#ap-table tbody tr").count() == 4
    assert page.locator("#delta-table tbody tr").count() == 2
    assert "Sim-GT Pretrain" in page.locator("#only-b").inner_text()
    assert page.locator("#settings-table tbody tr", has_text="fractions").count() == 1
    assert page.locator("#sweep-a").inner_text().startswith("A: a")
    assert page.errors == []
    assert page.requests == [html.as_uri()]
