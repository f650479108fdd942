"""Tests for the ``vlm`` material backend against a loopback chat-completions server."""

from __future__ import annotations

import base64
import json
import time
import urllib.error
import urllib.request

import cv2
import numpy as np
import pytest

from sim2radar.camera import CameraIntrinsics
from sim2radar.reconstruct.materials_vlm import (
    VlmError,
    VlmMaterials,
    VlmSetupError,
    build_prompt,
    parse_answer,
)
from sim2radar.reconstruct.types import (
    MATERIAL_BACKENDS,
    DepthResult,
    FrameInput,
    Segments,
)
from sim2radar.vocab import MATERIAL_CLASSES
from tests.reconstruct._vlm_server import VlmTestServer

EXPECTED = ["plasterboard", "ceramic_tile", "metal", "glass"]


@pytest.fixture(scope="module")
def scene():
    """40 x 30 image: wall (top), floor (bottom), a door and a window; 4 segments + 1 empty."""
    h, w = 30, 40
    rgb = np.zeros((h, w, 3), np.uint8)
    seg = np.full((h, w), -1, np.int32)
    seg[:20] = 0
    rgb[:20] = (200, 190, 170)
    seg[20:] = 1
    rgb[20:] = (110, 110, 120)
    seg[5:20, 4:12] = 2
    rgb[5:20, 4:12] = (150, 30, 30)
    seg[4:10, 24:36] = 3
    rgb[4:10, 24:36] = (170, 200, 230)
    k = CameraIntrinsics.from_fov(w, h, 60)
    frame = FrameInput(rgb, k, name="vlm-test")
    segs = Segments(seg, ("wall", "floor", "door", "window", "clutter"),
                    np.ones(5, np.float32))
    depth = DepthResult(np.full((h, w), 3.0, np.float32))
    return frame, depth, segs


def _backend(server, **kw):
    opts = dict(base_url=server.base_url, model="test-vlm", timeout_s=2.0, backoff_s=0.01,
                max_retries=2, max_concurrency=2)
    opts.update(kw)
    return VlmMaterials(**opts)


def test_registered():
    assert MATERIAL_BACKENDS.get("vlm") is VlmMaterials


def test_correct_json_and_request_contents(scene):
    frame, depth, segs = scene
    with VlmTestServer("json") as srv:
        backend = _backend(srv)
        labels = backend.label(frame, depth, segs)
        assert [lab.material for lab in labels[:4]] == EXPECTED
        assert labels[4].material == "unknown" and "no pixels" in labels[4].reason
        assert all(lab.confidence == pytest.approx(0.87) for lab in labels[:4])
        assert srv.n_requests == 4  # the empty segment is never sent
        body = srv.requests[0]
        assert body["model"] == "test-vlm"
        assert body["response_format"]["type"] == "json_schema"
        schema = body["response_format"]["json_schema"]["schema"]
        assert schema["properties"]["material"]["enum"] == list(MATERIAL_CLASSES)
        parts = body["messages"][1]["content"]
        images = [p for p in parts if p["type"] == "image_url"]
        assert len(images) == 2  # crop + outlined context
        png = base64.b64decode(images[0]["image_url"]["url"].split(",", 1)[1])
        crop = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
        assert crop is not None and crop.shape[2] == 3


@pytest.mark.parametrize("mode", ["prose", "fence"])
def test_json_inside_prose_or_fences_is_extracted(scene, mode):
    frame, depth, segs = scene
    with VlmTestServer(mode) as srv:
        labels = _backend(srv).label(frame, depth, segs)
    assert [lab.material for lab in labels[:4]] == EXPECTED


def test_garbage_and_out_of_vocabulary_become_unknown_with_reason(scene, caplog):
    frame, depth, segs = scene
    with VlmTestServer("garbage") as srv:
        backend = _backend(srv)
        labels = backend.label(frame, depth, segs)
        assert srv.n_requests == 4  # a bad answer is not retried
    assert all(lab.material == "unknown" and lab.confidence == 0 for lab in labels)
    assert "no JSON object" in labels[0].reason
    assert backend.stats["fallbacks"] == 4
    assert "labelled unknown" in caplog.text
    with VlmTestServer("oov") as srv:
        labels = _backend(srv).label(frame, depth, segs)
    assert labels[2].material == "unknown"
    assert "out-of-vocabulary material 'unobtainium'" in labels[2].reason


def test_timeout_then_success_on_retry(scene):
    frame, depth, segs = scene
    with VlmTestServer("json", n_slow=1, slow_s=0.8) as srv:
        backend = _backend(srv, timeout_s=0.3, max_concurrency=1)
        labels = backend.label(frame, depth, segs)
        assert [lab.material for lab in labels[:4]] == EXPECTED
        assert backend.stats["retries"] == 1
        assert srv.n_requests == 5


def test_http_500_then_success(scene):
    frame, depth, segs = scene
    with VlmTestServer("json", n_fail=2) as srv:
        backend = _backend(srv, max_concurrency=1)
        labels = backend.label(frame, depth, segs)
        assert [lab.material for lab in labels[:4]] == EXPECTED
        assert backend.stats["retries"] == 2 and srv.n_requests == 6


def test_server_down_raises_or_records_fallback(scene):
    frame, depth, segs = scene
    srv = VlmTestServer("json")
    url = srv.base_url
    srv.close()  # nothing listens on this port any more
    backend = VlmMaterials(base_url=url, max_retries=1, backoff_s=0.01, timeout_s=1.0)
    with pytest.raises(VlmError, match="after 2 attempts.*Is the server running"):
        backend.label(frame, depth, segs)
    fb = VlmMaterials(base_url=url, max_retries=1, backoff_s=0.01, timeout_s=1.0,
                      on_error="unknown")
    labels = fb.label(frame, depth, segs)
    assert all(lab.material == "unknown" for lab in labels)
    assert "VLM request failed" in labels[0].reason


def test_client_error_is_not_retried(scene):
    frame, depth, segs = scene
    with VlmTestServer("json") as srv:
        backend = VlmMaterials(base_url=srv.base_url.replace("/v1", "/wrong"), max_retries=3,
                               backoff_s=0.01, max_concurrency=1)
        with pytest.raises(VlmError, match="HTTP 404"):
            backend.label(frame, depth, segs)
        assert srv.n_requests == 1


def test_cache_hits_make_no_requests(scene, tmp_path):
    frame, depth, segs = scene
    cache = tmp_path / "vlm-cache.sqlite"
    with VlmTestServer("json") as srv:
        first = _backend(srv, cache_path=str(cache)).label(frame, depth, segs)
        assert srv.n_requests == 4
        second_backend = _backend(srv, cache_path=str(cache))
        second = second_backend.label(frame, depth, segs)
        assert srv.n_requests == 4  # all from the cache
        assert second_backend.stats["cache_hits"] == 4
        assert [a.material for a in first] == [b.material for b in second]
        # A new prompt version or model invalidates the cache.
        _backend(srv, cache_path=str(cache), prompt_version="v2").label(frame, depth, segs)
        assert srv.n_requests == 8


def test_invalid_answers_are_not_cached(scene, tmp_path):
    frame, depth, segs = scene
    cache = tmp_path / "c.sqlite"
    with VlmTestServer("garbage") as srv:
        _backend(srv, cache_path=str(cache)).label(frame, depth, segs)
        _backend(srv, cache_path=str(cache)).label(frame, depth, segs)
        assert srv.n_requests == 8


def test_concurrency_limit_is_respected(scene):
    frame, depth, segs = scene
    many = Segments(segs.segment_id, segs.labels[:4], segs.scores[:4])
    # the delay is long enough for two requests to overlap on a loaded 2-core machine
    with VlmTestServer("json", delay_s=0.4) as srv:
        _backend(srv, max_concurrency=2).label(frame, depth, many)
        assert srv.max_in_flight == 2  # parallel, but never more than the limit
    with VlmTestServer("json", delay_s=0.05) as srv:
        _backend(srv, max_concurrency=1).label(frame, depth, many)
        assert srv.max_in_flight == 1


def test_server_without_response_format_support(scene):
    frame, depth, segs = scene
    with VlmTestServer("no_rf") as srv:
        backend = _backend(srv, max_concurrency=1)
        labels = backend.label(frame, depth, segs)
        assert [lab.material for lab in labels[:4]] == EXPECTED
        assert srv.n_requests == 5  # one 400, then everything without response_format
        assert "response_format" not in srv.requests[-1]


def test_parse_answer_validation():
    lab = parse_answer('{"material": "Ceramic Tile", "confidence": 1.7, "reason": "floor"}')
    assert lab.material == "ceramic_tile" and lab.confidence == 1.0
    lab = parse_answer('{"material": "metal", "reason": "fire door"}')
    assert lab.confidence == 0.5 and "invalid" in lab.reason
    assert parse_answer(json.dumps({"material": "glass", "confidence": 0.2})).material == "glass"
    with pytest.raises(ValueError, match="out-of-vocabulary"):
        parse_answer('{"material": "steel", "confidence": 0.9}')
    with pytest.raises(ValueError):
        parse_answer("")
    assert '"door"' in build_prompt("door", True) and "fire" in build_prompt("door", True)


def test_bad_options():
    with pytest.raises(ValueError, match="known options"):
        VlmMaterials(url="http://x")
    with pytest.raises(ValueError, match="base_url"):
        VlmMaterials(base_url="localhost:8000")
    with pytest.raises(ValueError, match="on_error"):
        VlmMaterials(on_error="ignore")


# --- a misconfigured server stops the run, whatever on_error says -------------------------------


def _one_line_error(excinfo) -> str:
    msg = str(excinfo.value)
    assert "\n" not in msg, msg
    return msg


@pytest.mark.parametrize("on_error", ["unknown", "raise"])
def test_a_model_name_the_server_does_not_serve_stops_with_the_served_names(scene, on_error):
    """vLLM started from a local folder serves it under the folder's path: asking for the hub name
    is HTTP 404 on every request; before it, GET /v1/models says so, once."""
    frame, depth, segs = scene
    with VlmTestServer("json", served_models=("/models/internvl",)) as srv:
        backend = _backend(srv, model="OpenGVLab/InternVL2_5-8B", on_error=on_error)
        with pytest.raises(VlmSetupError) as err:
            backend.label(frame, depth, segs)
        assert _one_line_error(err) == (
            f"the server at {srv.base_url} serves ['/models/internvl'], not "
            "'OpenGVLab/InternVL2_5-8B': set materials.options.model to one of them, or start "
            "vLLM with --served-model-name OpenGVLab/InternVL2_5-8B (LMDeploy: --model-name "
            "OpenGVLab/InternVL2_5-8B)")
        assert srv.n_requests == 0 and srv.model_queries == 1  # no segment was sent
        with pytest.raises(VlmSetupError, match="serves"):  # the next frame: at once, no query
            backend.label(frame, depth, segs)
        assert srv.model_queries == 1 and backend.stats["fallbacks"] == 0


def test_the_model_list_is_asked_once_and_a_served_name_labels(scene):
    frame, depth, segs = scene
    with VlmTestServer("json", served_models=("other", "test-vlm")) as srv:
        backend = _backend(srv)
        for _ in range(2):
            labels = backend.label(frame, depth, segs)
        assert [lab.material for lab in labels[:4]] == EXPECTED
        assert srv.model_queries == 1
        assert "serves 'test-vlm'" in backend.check()


@pytest.mark.parametrize("status", [401, 403])
def test_a_refused_or_missing_api_key_stops_naming_the_variable(scene, monkeypatch, status):
    frame, depth, segs = scene
    monkeypatch.delenv("SIM2RADAR_VLM_API_KEY", raising=False)
    with VlmTestServer("json", api_key="s3cret", auth_status=status) as srv:
        with pytest.raises(VlmSetupError) as err:
            _backend(srv, on_error="unknown").label(frame, depth, segs)
        msg = _one_line_error(err)
        assert f"HTTP {status}" in msg and "none was sent" in msg
        assert "export SIM2RADAR_VLM_API_KEY=" in msg
        monkeypatch.setenv("SIM2RADAR_VLM_API_KEY", "wrong")
        with pytest.raises(VlmSetupError, match=r"refused the API key in \$SIM2RADAR_VLM_API_KEY"):
            _backend(srv, on_error="unknown").label(frame, depth, segs)
        assert srv.n_requests == 0
        monkeypatch.setenv("SIM2RADAR_VLM_API_KEY", "s3cret")
        labels = _backend(srv).label(frame, depth, segs)
        assert [lab.material for lab in labels[:4]] == EXPECTED


def test_http_404_on_chat_stops_even_when_the_server_lists_no_models(scene):
    """A server without GET /v1/models cannot be asked first: the chat request's 404 stops."""
    frame, depth, segs = scene
    with VlmTestServer("json", list_models=False) as srv:
        backend = _backend(srv, model="OpenGVLab/InternVL2_5-8B", on_error="unknown",
                           max_concurrency=1)
        assert "does not list its models" in backend.check()
        with pytest.raises(VlmSetupError) as err:
            backend.label(frame, depth, segs)
        msg = _one_line_error(err)
        assert "HTTP 404" in msg and "does not exist" in msg and "materials.options.model" in msg
        assert srv.n_requests == 1  # not retried, and no segment after it is sent
        assert backend.stats["fallbacks"] == 0


def test_too_few_images_per_prompt_stops_naming_limit_mm_per_prompt(scene):
    frame, depth, segs = scene
    with VlmTestServer("json", max_images=1) as srv:
        with pytest.raises(VlmSetupError) as err:
            _backend(srv, on_error="unknown", max_concurrency=1).label(frame, depth, segs)
        msg = _one_line_error(err)
        assert """--limit-mm-per-prompt '{"image": 2}'""" in msg and "send_context: false" in msg
        assert srv.n_requests == 1  # not mistaken for a rejected response_format
        labels = _backend(srv, send_context=False).label(frame, depth, segs)
        assert [lab.material for lab in labels[:4]] == EXPECTED


def test_on_error_unknown_still_covers_a_server_that_is_down(scene):
    """Network errors stay retried and, with on_error: unknown, recorded per segment."""
    frame, depth, segs = scene
    srv = VlmTestServer("json")
    url = srv.base_url
    srv.close()
    backend = VlmMaterials(base_url=url, model="test-vlm", max_retries=0, timeout_s=1.0,
                           on_error="unknown")
    with pytest.raises(VlmError, match="cannot reach"):
        backend.check()
    labels = backend.label(frame, depth, segs)
    assert all(lab.material == "unknown" for lab in labels)


def test_the_test_server_binds_loopback_and_stops_by_itself():
    srv = VlmTestServer("json", lifetime_s=0.3)
    assert srv.httpd.server_address[0] == "127.0.0.1"
    with urllib.request.urlopen(srv.base_url + "/models", timeout=2) as resp:
        assert json.loads(resp.read())["data"][0]["id"] == "test-vlm"
    time.sleep(0.8)
    with pytest.raises(urllib.error.URLError):
        urllib.request.urlopen(srv.base_url + "/models", timeout=2)
    srv.close()  # idempotent
