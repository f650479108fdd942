"""ServerWatch tells a server that is gone from one that is only busy."""

from __future__ import annotations

import socket
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from sim2radar.cli._app import ServerWatch


class _Slow(BaseHTTPRequestHandler):
    def do_GET(self):  # noqa: N802 - http.server's name
        time.sleep(2.5)                    # longer than the watch's 2 s timeout
        self.send_response(200)
        self.end_headers()

    def log_message(self, *args):
        pass


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_refusing_server_is_gone_at_once_a_busy_one_only_after_busy_s():
    refused = ServerWatch(f"http://127.0.0.1:{_free_port()}/api", interval_s=0.05)
    with refused:
        assert refused.gone.wait(5.0)      # nothing listens there: two refusals
    server = ThreadingHTTPServer(("127.0.0.1", 0), _Slow)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{server.server_address[1]}/api"
    try:
        patient = ServerWatch(url, interval_s=0.05, busy_s=60.0)
        with patient:
            assert not patient.gone.wait(5.0)   # two time-outs in a row: busy, not gone
        impatient = ServerWatch(url, interval_s=0.05, busy_s=3.0)
        with impatient:
            assert impatient.gone.wait(12.0) and "timed out" in impatient.why
    finally:
        server.shutdown()
        server.server_close()
