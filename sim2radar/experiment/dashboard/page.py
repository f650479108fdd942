"""The dashboard's page: the Jinja2 template and the static script and style of
``sim2radar/experiment/page/`` (package data), filled with :func:`~.data.dashboard_data`'s
document.

    render_html(data, live=False) -> str     the page: Plotly's JS, script, style, data inline
    write_dashboard(folder, out_path)        load, render and write one sweep's page atomically
    render_compare_html(data) -> str         the comparison page of two sweeps
                                             (:func:`~.compare.compare_data`'s document)
    write_comparison(a, b, out_path)         load both, render and write it atomically

The page is one self-contained file that works offline: Plotly's bundle, the script, the style,
the data (the sim–real gap figures as Plotly figures of ``gap.json``'s numbers, PNGs as
``data:`` URIs only for an older report) are inline, and a Content-Security-Policy in the page
forbids loading anything else. The comparison page is made the same way from its own template
and script (``compare.html.j2``, ``compare.js``), with the same style and ``common.js``. The live page polls ``data.json`` every ``poll_s``
seconds and re-renders in place (``Plotly.react``, rebuilt tables), so runs appear as the sweep
finishes them, without a reload.
"""

from __future__ import annotations

import functools
import html
import importlib.resources
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sim2radar.experiment.dashboard.compare import compare_data
from sim2radar.experiment.dashboard.data import dashboard_data, load_sweep
from sim2radar.fileio import atomic_write

__all__ = ["PAGE_FILES", "POLL_S", "render_compare_html", "render_html", "write_comparison",
           "write_dashboard"]

#: seconds between the live page's polls of ``data.json``
POLL_S = 3.0
#: the page's files in the package data folder ``sim2radar/experiment/page/``, by role
PAGE_FILES = {"template": "dashboard.html.j2", "script": "dashboard.js",
              "style": "dashboard.css", "common": "common.js",
              "compare_template": "compare.html.j2", "compare_script": "compare.js"}
#: the page loads nothing: inline scripts and styles, images as data: URIs, and (live) its own
#: data.json; fonts, frames and every other fetch are refused by the browser
_CSP = ("default-src 'none'; script-src 'unsafe-inline'; "
        "style-src 'unsafe-inline'; img-src data: blob:; font-src data:; "
        "connect-src {connect}; base-uri 'none'; form-action 'none'")


def _page_file(role: str) -> str:
    """The text of one of :data:`PAGE_FILES`, read through :mod:`importlib.resources` (so it is
    found the same from a clone, an editable install and a wheel)."""
    return (importlib.resources.files("sim2radar.experiment") / "page" / PAGE_FILES[role]
            ).read_text(encoding="utf-8")


def _inline(text: str, element: str, what: str) -> Any:
    """``text`` marked safe for the template, inside ``<element>``: refused if it could close
    the element (an HTML parser ends a ``<script>`` at the first ``</script``)."""
    from markupsafe import Markup

    if f"</{element}" in text.lower():
        raise RuntimeError(f"{what} contains '</{element}': it cannot be inlined")
    return Markup(text)


def _escape(value: Any) -> Any:
    """The template's escaping of every ``{{ value }}``: :func:`html.escape` (``'`` as
    ``&#x27;``, as the page has always written it); Markup (the inline blobs) passes as is."""
    from markupsafe import Markup

    return value if isinstance(value, Markup) else Markup(html.escape(str(value)))


@functools.cache
def _template(role: str = "template") -> Any:
    """A page's compiled Jinja2 template (autoescaped; StrictUndefined: a missing variable is
    an error, not an empty string)."""
    import jinja2

    env = jinja2.Environment(autoescape=True, undefined=jinja2.StrictUndefined,
                             finalize=_escape)
    return env.from_string(_page_file(role))


@functools.cache
def _static() -> dict[str, Any]:
    """The page's script and style, and Plotly's bundle, checked and marked safe to inline."""
    from plotly.offline import get_plotlyjs

    # plotly's own to_html relies on the same property of its bundle
    return {"plotly_js": _inline(get_plotlyjs(), "script", "the Plotly bundle"),
            "common_js": _inline(_page_file("common"), "script", PAGE_FILES["common"]),
            "css": _inline(_page_file("style"), "style", PAGE_FILES["style"])}


def _script(role: str) -> Any:
    """A page's own script (``script`` or ``compare_script``), checked and marked safe."""
    return _inline(_page_file(role), "script", PAGE_FILES[role])


def _script_json(doc: Any) -> Any:
    """JSON for an inline ``<script type="application/json">``: ``<``, ``>``, ``&`` escaped so
    no text in the data can close the element."""
    from markupsafe import Markup

    text = json.dumps(doc, allow_nan=False, separators=(",", ":"), ensure_ascii=False)
    return Markup(text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")
                  .replace("\u2028", "\\u2028").replace("\u2029", "\\u2029"))


def render_html(data: Mapping[str, Any], *, live: bool = False, poll_s: float = POLL_S,
                data_url: str = "data.json") -> str:
    """The dashboard page: one self-contained HTML document.

    Parameters
    ----------
    data : :func:`~.data.dashboard_data`'s dict.
    live : poll ``data_url`` every ``poll_s`` seconds and re-render when it changed; for the
        page :func:`~.server.serve_dashboard` serves.
    poll_s : seconds between polls [s] (live only).
    data_url : the live page's data (relative to the page, or ``/data.json`` for a page that
        is also served below the root, at ``/run/<id>``).

    Returns
    -------
    str — HTML with Plotly's bundle, the page's script and style and the data inline; a
    Content-Security-Policy lets it load nothing else (the live page: its own origin's
    ``data.json``).
    """
    if live and not poll_s > 0:
        raise ValueError(f"poll_s must be > 0, got {poll_s}")
    banner = data.get("banner") or {"kind": "unknown", "text": ""}
    folder = data.get("folder", "")
    footer = (f"Live view of {folder}; new runs appear as they finish." if live
              else f"Static snapshot of {folder}. For a live view while the "
                   f"sweep runs: sim2radar dashboard {data.get('folder', 'SWEEP')} --serve")
    poll_ms = int(round(1000 * poll_s)) if live else 0
    return _template().render(
        csp=_CSP.format(connect="'self'" if live else "'none'"),
        page_title=f"sim2radar sweep {data.get('name', '')}",
        title=f"Sweep {data.get('name', '')}",
        live_line="live · polling for new runs" if live else "static snapshot",
        banner_kind=str(banner.get("kind", "unknown")),
        banner_text=str(banner.get("text", "")),
        footer=footer,
        data_json=_script_json(data),
        live_json=_script_json({"poll_ms": poll_ms, "data_url": data_url}),
        js=_script("script"),
        **_static())


def render_compare_html(data: Mapping[str, Any]) -> str:
    """The comparison page of two sweeps: one self-contained HTML document, offline as the
    dashboard (Plotly's bundle, script, style and data inline; a Content-Security-Policy lets
    it load nothing).

    Parameters
    ----------
    data : :func:`~.compare.compare_data`'s dict.
    """
    a, b = data.get("a") or {}, data.get("b") or {}
    names = f"{a.get('name', 'A')} vs {b.get('name', 'B')}"
    return _template("compare_template").render(
        csp=_CSP.format(connect="'none'"),
        page_title=f"sim2radar sweeps {names}",
        title=f"Sweeps compared: {names}",
        footer=(f"Static comparison of {a.get('folder', 'A')} (A) and {b.get('folder', 'B')} "
                f"(B). Each sweep's own page: sim2radar dashboard SWEEP --out FILE.html"),
        data_json=_script_json(data),
        js=_script("compare_script"),
        **_static())


def write_comparison(folder_a: str | os.PathLike, folder_b: str | os.PathLike,
                     out_path: str | os.PathLike) -> Path:
    """Write the comparison page of the sweeps in ``folder_a`` (A, the reference) and
    ``folder_b`` (B) to ``out_path`` (atomically; the parent folders are made). Returns
    ``out_path``.

    Raises
    ------
    SweepFolderError — see :func:`~.data.load_sweep`.
    """
    page = render_compare_html(compare_data(load_sweep(folder_a), load_sweep(folder_b)))
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write(out, page.encode("utf-8"))


def write_dashboard(folder: str | os.PathLike, out_path: str | os.PathLike) -> Path:
    """Write the static dashboard of the sweep in ``folder`` to ``out_path`` (atomically:
    :func:`sim2radar.fileio.atomic_write`; the parent folders are made). Returns ``out_path``.

    Raises
    ------
    SweepFolderError — see :func:`~.data.load_sweep`.
    """
    page = render_html(dashboard_data(load_sweep(folder)))
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write(out, page.encode("utf-8"))
