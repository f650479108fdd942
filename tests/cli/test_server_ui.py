"""The managed Prefect server's UI (``sim2radar/cli/server.py``) on its own port (issue #24).

The probe: the managed server runs on a free port, but its ``/ui-settings`` answered Prefect's
default ``"api_url": "http://127.0.0.1:4200/api"``, so the UI called a port nobody listens on
and showed "Oops. Something went wrong.". Here a real managed server on a fresh
``PREFECT_HOME`` tells its UI its own address, and (in headless Chromium, when installed) the
UI shows a finished tiny ``sim2radar generate`` run with its task runs, every API call going
to that server. The server is stopped at teardown; 127.0.0.1 only. About 30 s on 2 cores.
"""

from __future__ import annotations

import json
import os
import signal
import urllib.request
from pathlib import Path

import pytest

from sim2radar.cli import server as srv
from tests.cli.test_server import _generate, _processes_of

CHROMIUM = Path("/usr/bin/chromium")
TIMEOUT_MS = 30_000

pytestmark = pytest.mark.skipif(not Path("/proc/self/environ").exists(),
                                reason="finds the server's processes through Linux /proc")


@pytest.fixture(scope="module")
def managed(tmp_path_factory):
    """A managed server started on a fresh PREFECT_HOME: ``(home, state)``."""
    home = (tmp_path_factory.mktemp("server-ui") / "prefect").resolve()
    try:
        state, started = srv.ensure_server(home)
        assert started
        yield home, state
    finally:
        srv.stop_server(home)
        for pid in _processes_of(home):  # anything left over, even after a failure
            os.kill(pid, signal.SIGKILL)


def _post(url: str, doc: dict) -> list[dict]:
    req = urllib.request.Request(url, data=json.dumps(doc).encode(), method="POST",
                                 headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=10) as r:
        return json.load(r)


def test_the_managed_servers_ui_is_told_its_own_port(managed):
    _, state = managed
    with urllib.request.urlopen(f"{state.ui_url}/ui-settings", timeout=10) as r:
        settings = json.load(r)
    assert settings["api_url"] == f"http://127.0.0.1:{state.port}/api" == state.api_url


def test_the_managed_servers_ui_lists_a_finished_run_and_its_task_runs(managed, tmp_path):
    if not CHROMIUM.exists():
        pytest.skip(f"{CHROMIUM} not found (`make setup` installs Debian's chromium)")
    playwright = pytest.importorskip("playwright.sync_api",
                                     reason="the playwright package is missing")
    from tests.experiment.test_dashboard_browser import CHROMIUM_ARGS

    home, state = managed
    run = _generate(home, tmp_path / "store", "--frames", "1")  # reuses the managed server
    assert run.returncode == 0, run.stderr[-3000:]
    assert "started the local Prefect server" not in run.stderr
    flow_runs = [fr for fr in _post(f"{state.api_url}/flow_runs/filter", {})
                 if fr["state"]["type"] == "COMPLETED"]
    assert flow_runs, "no completed flow run recorded"
    flow_run = flow_runs[0]
    task_runs = _post(f"{state.api_url}/task_runs/filter",
                      {"flow_runs": {"id": {"any_": [flow_run["id"]]}}})
    assert task_runs, "the flow run recorded no task runs"

    with playwright.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS,
                                     headless=True)
        try:
            page = browser.new_page(viewport={"width": 1280, "height": 900})
            page.set_default_timeout(TIMEOUT_MS)
            api_calls = []
            page.on("request", lambda r: api_calls.append(r.url) if "/api/" in r.url else None)
            page.goto(f"{state.ui_url}/runs")
            page.get_by_text(flow_run["name"]).first.wait_for()  # listed among the runs
            page.goto(f"{state.ui_url}/runs/flow-run/{flow_run['id']}")
            page.get_by_text(flow_run["name"]).first.wait_for()
            page.get_by_text("Task Runs", exact=True).first.click()
            page.get_by_text(task_runs[0]["name"]).first.wait_for()  # and its task runs
            assert "Something went wrong" not in page.inner_text("body")
        finally:
            browser.close()
    assert api_calls and all(u.startswith(f"{state.api_url}/") for u in api_calls), api_calls
