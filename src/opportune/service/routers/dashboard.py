"""The pages (the dashboard, a run's page, the API's reader, served from the package) and ``/healthz``."""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, FastAPI
from fastapi.responses import FileResponse
from fastapi.staticfiles import StaticFiles

from opportune import __version__
from opportune.service.routers.depends import RUN_ID
from opportune.service.schemas import Health, errors
from opportune.service.storage import Store

__all__ = ["STATIC", "mount_static", "router"]

#: The pages, scripts and styles, shipped in the package (nothing is fetched from elsewhere).
STATIC = Path(__file__).parent.parent / "static"


def router(store: Store) -> APIRouter:
    """The pages, and the liveness check that reads ``store``."""
    api = APIRouter()

    @api.get("/", include_in_schema=False)
    def index():
        return FileResponse(STATIC / "index.html", media_type="text/html")

    @api.get("/ui/runs/{run_id}", include_in_schema=False)
    def run_page(run_id: int = RUN_ID):
        return FileResponse(STATIC / "run.html", media_type="text/html")

    @api.get("/favicon.ico", include_in_schema=False)
    def favicon():
        return FileResponse(STATIC / "favicon.svg", media_type="image/svg+xml")

    @api.get("/docs", include_in_schema=False)
    def docs():
        return FileResponse(STATIC / "docs.html", media_type="text/html")

    @api.get("/healthz", tags=["service"], operation_id="health",
             summary="Liveness: the service answers and its database is reachable",
             responses={200: {"model": Health, "description": "The service and its database answer"},
                        **errors({500: ["internal_error"]})})
    def healthz():
        return {"ok": True, "version": __version__, "journal_mode": store.journal_mode()}

    return api


def mount_static(app: FastAPI) -> None:
    """Serve :data:`STATIC` at ``/static``."""
    app.mount("/static", StaticFiles(directory=STATIC), name="static")
