"""The web view and the OpenAPI docs, every asset served by the service itself (robot networks
are often offline: no CDN).

- ``/``: the sites, live; ``/sites/{site_id}``: one site's floorplan, fragments, status,
  robots, uploads and downloads, live through its server-sent events. Plain HTML, JavaScript
  and SVG from ``api/web/static/`` (package data), mounted at ``/static/web``.
- ``/docs``: Swagger UI from the ``swagger-ui-bundle-v2`` package, mounted at
  ``/static/swagger-ui``.

Pages and assets hold no site data and need no token; the data they fetch does. With
``FPJ_TOKENS`` set, the pages ask for a token once (or take ``?token=``), keep it in the
browser's localStorage and send it as ``Authorization: Bearer`` (the event stream as
``?access_token=``, the one route that accepts it).
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

from fastapi import APIRouter, FastAPI, Request
from fastapi.openapi.docs import get_swagger_ui_html, get_swagger_ui_oauth2_redirect_html
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles

from api.deps import SiteId

__all__ = ["STATIC_DIR", "install_web", "router"]

STATIC_DIR = Path(str(files("api") / "web" / "static"))
_SWAGGER_MOUNT = "/static/swagger-ui"
_NO_STORE = {"Cache-Control": "no-cache"}

router = APIRouter(include_in_schema=False)


def _page(name: str) -> HTMLResponse:
    return HTMLResponse((STATIC_DIR / name).read_text(encoding="utf-8"), headers=_NO_STORE)


@router.get("/", response_class=HTMLResponse)
async def sites_page() -> HTMLResponse:
    return _page("index.html")


@router.get("/sites/{site_id}", response_class=HTMLResponse)
async def site_page(site_id: SiteId) -> HTMLResponse:
    return _page("site.html")


@router.get("/docs", response_class=HTMLResponse)
async def swagger_ui(request: Request) -> HTMLResponse:
    root = request.scope.get("root_path", "")
    return get_swagger_ui_html(
        openapi_url=f"{root}{request.app.openapi_url}",
        title=f"{request.app.title} - API docs",
        swagger_js_url=f"{root}{_SWAGGER_MOUNT}/swagger-ui-bundle.js",
        swagger_css_url=f"{root}{_SWAGGER_MOUNT}/swagger-ui.css",
        swagger_favicon_url=f"{root}{_SWAGGER_MOUNT}/favicon-32x32.png",
        oauth2_redirect_url=f"{root}/docs/oauth2-redirect",
        swagger_ui_parameters={"validatorUrl": None},  # no call to an online validator
    )


@router.get("/docs/oauth2-redirect", response_class=HTMLResponse)
async def swagger_ui_redirect() -> HTMLResponse:
    return get_swagger_ui_oauth2_redirect_html()


def install_web(app: FastAPI) -> None:
    """Add the pages, the docs and their static files to ``app`` (built with
    ``docs_url=None`` and ``redoc_url=None``)."""
    from swagger_ui_bundle import swagger_ui_path

    app.mount("/static/web", StaticFiles(directory=STATIC_DIR), name="web")
    app.mount(_SWAGGER_MOUNT, StaticFiles(directory=str(swagger_ui_path)), name="swagger-ui")
    app.include_router(router)
