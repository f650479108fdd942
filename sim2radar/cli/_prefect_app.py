"""The app the managed Prefect server runs (``uvicorn --factory``): Prefect's own server app
(API, UI, services) plus ``GET /sim2radar/server``, which answers the ``PREFECT_HOME`` the
server was started for and the token its record holds. A command trusts a recorded server
only when it answers both (:mod:`sim2radar.cli.server`): a record copied from another home, or
a port that another server took after ours died, is never taken for ours.
"""

from __future__ import annotations

import os

__all__ = ["IDENTITY_PATH", "TOKEN_ENV", "create_app"]

#: Where the server answers who it is.
IDENTITY_PATH = "/sim2radar/server"
#: The environment variable the server's token is passed in.
TOKEN_ENV = "SIM2RADAR_SERVER_TOKEN"


def create_app():
    """Prefect's ``create_app()`` with the identity route in front of its UI mount."""
    from prefect.server.api.server import create_app as prefect_app
    from starlette.responses import JSONResponse
    from starlette.routing import Route

    app = prefect_app()
    identity = {"home": os.environ.get("PREFECT_HOME", ""),
                "token": os.environ.get(TOKEN_ENV, ""), "pid": os.getpid()}

    async def whoami(request):  # noqa: ARG001 - Starlette's endpoint signature
        return JSONResponse(identity)

    # first: the UI is mounted at "/" and would answer every path after it
    app.router.routes.insert(0, Route(IDENTITY_PATH, whoami, methods=["GET"]))
    return app
