"""A loopback HTTP server speaking OpenAI chat-completions, with scripted misbehaviour.

Binds 127.0.0.1 on an ephemeral port, serves from a daemon thread, stops on ``close()`` (use it
as a context manager) and in any case by itself after ``lifetime_s``. The answer's material
follows the semantic label named in the prompt: door -> metal, floor -> ceramic_tile,
wall -> plasterboard, window -> glass, else concrete.

Like vLLM's OpenAI server: ``GET /v1/models`` lists ``served_models`` (HTTP 404 when
``list_models`` is off; counted in ``model_queries``); a chat request for a model it does not
serve gets HTTP 404 "The model `X` does not exist."; with ``api_key`` set, a request without
``Authorization: Bearer <api_key>`` gets ``auth_status`` (401, or 403); with ``max_images`` set,
more images in one request get HTTP 400 "At most N image(s) may be provided in one request.".

Modes (``mode``):
  json      bare JSON answer                     prose   JSON inside prose
  fence     JSON in a ```json fence              garbage text without JSON
  oov       material "unobtainium"               no_rf   HTTP 400 when response_format is sent
Independent of the mode: the first ``n_slow`` requests sleep ``slow_s`` before answering, the
first ``n_fail`` requests get HTTP 500, ``delay_s`` is added to every request (to observe the
number of requests in flight, recorded in ``max_in_flight``).
"""

from __future__ import annotations

import json
import re
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

MATERIAL_FOR = {"door": "metal", "floor": "ceramic_tile", "wall": "plasterboard",
                "window": "glass"}


class VlmTestServer:
    def __init__(self, mode: str = "json", *, n_slow: int = 0, slow_s: float = 0.0,
                 n_fail: int = 0, delay_s: float = 0.0,
                 served_models: tuple[str, ...] = ("test-vlm",), list_models: bool = True,
                 api_key: str | None = None, auth_status: int = 401,
                 max_images: int | None = None, lifetime_s: float = 300.0) -> None:
        self.mode = mode
        self.n_slow, self.slow_s, self.n_fail, self.delay_s = n_slow, slow_s, n_fail, delay_s
        self.served_models, self.list_models = list(served_models), list_models
        self.api_key, self.auth_status, self.max_images = api_key, auth_status, max_images
        self.model_queries = 0
        self.requests: list[dict] = []
        self._closed = False
        self.in_flight = 0
        self.max_in_flight = 0
        self._lock = threading.Lock()
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):  # keep test output quiet
                pass

            def do_POST(self):  # noqa: N802 (http.server API)
                outer._handle(self)

            def do_GET(self):  # noqa: N802 (http.server API)
                outer._handle_get(self)

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.httpd.daemon_threads = True
        self.thread = threading.Thread(target=self.httpd.serve_forever, kwargs={"poll_interval": 0.02},
                                       daemon=True)
        self.thread.start()
        self._timer = threading.Timer(lifetime_s, self.close)  # a forgotten server stops anyway
        self._timer.daemon = True
        self._timer.start()

    @property
    def base_url(self) -> str:
        return f"http://127.0.0.1:{self.httpd.server_address[1]}/v1"

    @property
    def n_requests(self) -> int:
        with self._lock:
            return len(self.requests)

    def close(self) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
        if threading.current_thread() is not self._timer:
            self._timer.cancel()
        self.httpd.shutdown()
        self.httpd.server_close()
        self.thread.join(timeout=5)

    def __enter__(self) -> VlmTestServer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -----------------------------------------------------------------------------------------
    def _authorised(self, h: BaseHTTPRequestHandler) -> bool:
        return self.api_key is None or h.headers.get("Authorization") == f"Bearer {self.api_key}"

    def _handle_get(self, h: BaseHTTPRequestHandler) -> None:
        with self._lock:
            self.model_queries += 1
        if not self._authorised(h):
            return self._send(h, self.auth_status, {"error": "Unauthorized"})
        if h.path != "/v1/models" or not self.list_models:
            return self._send(h, 404, {"detail": "Not Found"})
        self._send(h, 200, {"object": "list", "data": [
            {"id": m, "object": "model", "owned_by": "vllm", "root": m}
            for m in self.served_models]})

    def _handle(self, h: BaseHTTPRequestHandler) -> None:
        length = int(h.headers.get("Content-Length", 0))
        body = json.loads(h.rfile.read(length) or b"{}")
        with self._lock:
            self.requests.append(body)
            n = len(self.requests)
            self.in_flight += 1
            self.max_in_flight = max(self.max_in_flight, self.in_flight)
        done = False

        def finished() -> None:
            # the request stops counting as in flight once its answer is ready, *before* it is
            # written: the client may send its next request the moment it has read this one,
            # before this thread would reach a later decrement (a false "2 in flight")
            nonlocal done
            if not done:
                done = True
                with self._lock:
                    self.in_flight -= 1

        send = self._send

        def _send(h, code, doc):
            finished()
            send(h, code, doc)

        try:
            if not self._authorised(h):
                return _send(h, self.auth_status, {"error": "Unauthorized"})
            if h.path != "/v1/chat/completions":
                return _send(h, 404, {"error": f"no route {h.path}"})
            if body.get("model") not in self.served_models:
                return _send(h, 404, {"object": "error", "type": "NotFoundError", "code": 404,
                                      "message": f"The model `{body.get('model')}` does not "
                                                 "exist."})
            n_images = sum(1 for msg in body.get("messages", [])
                           if isinstance(msg.get("content"), list)
                           for part in msg["content"] if part.get("type") == "image_url")
            if self.max_images is not None and n_images > self.max_images:
                return _send(h, 400, {"object": "error", "type": "BadRequestError", "code": 400,
                                      "message": f"At most {self.max_images} image(s) may be "
                                                 "provided in one request."})
            if n <= self.n_slow:
                time.sleep(self.slow_s)
            if self.delay_s:
                time.sleep(self.delay_s)
            if n <= self.n_fail:
                return _send(h, 500, {"error": "internal error (scripted)"})
            if self.mode == "no_rf" and "response_format" in body:
                return _send(h, 400, {"error": "response_format is not supported"})
            text = self._answer(body)
            _send(h, 200, {
                "id": f"chatcmpl-{n}", "object": "chat.completion", "model": body.get("model"),
                "choices": [{"index": 0, "finish_reason": "stop",
                             "message": {"role": "assistant", "content": text}}],
            })
        except (BrokenPipeError, ConnectionResetError):
            pass  # the client gave up (timeout); fine
        finally:
            finished()

    def _answer(self, body: dict) -> str:
        prompt = ""
        for msg in body.get("messages", []):
            content = msg.get("content")
            parts = content if isinstance(content, list) else [{"type": "text", "text": content}]
            prompt += " ".join(p.get("text", "") for p in parts if p.get("type") == "text")
        m = re.search(r'labelled this segment "(\w+)"', prompt)
        label = m.group(1) if m else "unknown"
        material = MATERIAL_FOR.get(label, "concrete")
        if self.mode == "oov":
            material = "unobtainium"
        ans = json.dumps({"material": material, "confidence": 0.87,
                          "reason": f"{label}s in corridors are usually {material}"})
        if self.mode == "prose":
            return f"Looking at the image, this is a {label}. My answer: {ans} Hope it helps!"
        if self.mode == "fence":
            return f"Sure.\n```json\n{ans}\n```"
        if self.mode == "garbage":
            return "It is probably made of something shiny, I am not sure."
        return ans

    @staticmethod
    def _send(h: BaseHTTPRequestHandler, code: int, doc: dict) -> None:
        data = json.dumps(doc).encode()
        h.send_response(code)
        h.send_header("Content-Type", "application/json")
        h.send_header("Content-Length", str(len(data)))
        h.end_headers()
        h.wfile.write(data)
