"""The web view in a real browser: headless Chromium (Debian's ``chromium`` and
``chromedriver``, driven by selenium) opens a site's page on the real service (uvicorn, Redis 7,
worker processes); fragments uploaded over HTTP while the page is open appear, the status
changes, an ambiguous result's alternatives can be switched, all without a reload.

Screenshots are kept under ``out/test-artifacts/web/``. Skipped, saying why, when chromium,
chromedriver or selenium is missing (``make install`` installs them as root).
"""

from __future__ import annotations

import itertools
import math
import re
import shutil
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from api.colors import fragment_color
from services.point_io import encode_ply
from services.synthetic import SyntheticScene
from store.keys import Keys
from store.records import site_event
from tests.conftest import small_scene
from tests.service_fixtures import (
    ROOT,
    ApiServer,
    make_settings,
    ply_bytes,
)

pytestmark = pytest.mark.timeout(90)

CHROMIUM, CHROMEDRIVER = shutil.which("chromium"), shutil.which("chromedriver")
if CHROMIUM is None or CHROMEDRIVER is None:
    pytest.skip(
        "chromium and chromedriver are not installed (as root: apt-get install chromium "
        "chromium-driver, or make install)",
        allow_module_level=True,
    )
webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed")
from selenium.webdriver.chrome.service import Service  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.support.ui import WebDriverWait  # noqa: E402

ARTIFACTS = ROOT / "out" / "test-artifacts" / "web"
FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-dev-shm-usage",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--window-size=1400,1000",
)
SITE = "browser-site"


@pytest.fixture
def browser(tmp_path: Path) -> Iterator[Any]:
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in (*FLAGS, f"--user-data-dir={tmp_path / 'profile'}"):
        options.add_argument(flag)
    driver = webdriver.Chrome(options=options, service=Service(CHROMEDRIVER))
    driver.set_page_load_timeout(20)
    yield driver
    driver.quit()


def _shot(driver: Any, name: str) -> Path:
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    path = ARTIFACTS / name
    driver.save_screenshot(str(path))
    return path


def _wait(driver: Any, condition: Any, timeout: float, what: str) -> Any:
    return WebDriverWait(driver, timeout, poll_frequency=0.1).until(
        lambda d: condition(d), message=what
    )


def _walls(driver: Any) -> dict[str, Any]:
    return {
        e.get_attribute("data-fragment"): e
        for e in driver.find_elements(By.CSS_SELECTOR, "svg#plan polyline.wall")
    }


def _text(driver: Any, element_id: str) -> str:
    return str(driver.find_element(By.ID, element_id).text)


def _label_near_its_walls(driver: Any, fragment_id: str) -> float:
    """Pixel distance from the fragment's label to its wall chain (in the SVG's units)."""
    points, label = driver.execute_script(
        """
        const id = arguments[0];
        const wall = [...document.querySelectorAll('svg#plan polyline.wall')]
          .find((e) => e.dataset.fragment === id);
        const label = [...document.querySelectorAll('svg#plan text.label')]
          .find((e) => e.dataset.fragment === id);
        return [wall.getAttribute('points'),
                [Number(label.getAttribute('x')), Number(label.getAttribute('y'))]];
        """,
        fragment_id,
    )
    xy = [tuple(float(v) for v in p.split(",")) for p in points.split()]

    def to_segment(a: tuple[float, ...], b: tuple[float, ...]) -> float:
        dx, dy = b[0] - a[0], b[1] - a[1]
        t = ((label[0] - a[0]) * dx + (label[1] - a[1]) * dy) / max(dx * dx + dy * dy, 1e-9)
        t = min(1.0, max(0.0, t))
        return math.hypot(label[0] - a[0] - t * dx, label[1] - a[1] - t * dy)

    return min(to_segment(a, b) for a, b in itertools.pairwise(xy))


def _ambiguous(result: dict[str, Any]) -> dict[str, Any]:
    """The closed result turned ambiguous, its runner-up the room mirrored (x -> -x)."""
    mirror = [[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]

    def mirrored(pose: list[list[float]]) -> list[list[float]]:
        product = [
            [sum(mirror[i][k] * pose[k][j] for k in range(4)) for j in range(4)] for i in range(4)
        ]
        return product

    rooms = [
        {**room, "polygon": [[-x, y] for x, y in room["polygon"]][::-1]}
        for room in result["floorplan"]["rooms"]
    ]
    alternative = {
        "probability": 0.3,
        "fragments": [{"id": f["id"], "pose": mirrored(f["pose"])} for f in result["fragments"]],
        "floorplan": {"rooms": rooms},
    }
    return {**result, "status": "ambiguous", "confidence": 0.6, "alternatives": [alternative]}


def test_site_page_follows_uploads_live(
    server: ApiServer, browser: Any, redis_client: Any, tmp_path: Path
) -> None:
    started = time.monotonic()
    scene: SyntheticScene = small_scene("easy", 0)
    data = {f.id: encode_ply(f.points) for f in scene.fragments}
    ids = list(data)
    browser.get(f"{server.url}/sites/{SITE}")
    browser.execute_script("window.__notReloaded = true;")
    _wait(browser, lambda d: _text(d, "live") == "live", 10, "the event stream connects")
    assert _text(browser, "result-status") == "none yet"
    assert _walls(browser) == {}
    _shot(browser, "01-empty-site.png")

    with server.client() as http:
        # The first fragment over HTTP while the page is open: its row appears.
        assert (
            http.put(f"/v1/sites/{SITE}/fragments/{ids[0]}", content=data[ids[0]]).status_code
            == 202
        )
        _wait(
            browser,
            lambda d: d.find_elements(By.CSS_SELECTOR, f'#fragments tr[data-fragment="{ids[0]}"]'),
            10,
            "the first fragment's row appears",
        )
        # One through the page's own upload (the file input behind the drop zone) ...
        dropped = tmp_path / f"{ids[1]}.ply"
        dropped.write_bytes(data[ids[1]])
        browser.find_element(By.ID, "file-input").send_keys(str(dropped))
        # ... and the rest over HTTP.
        for fid in ids[2:]:
            assert (
                http.put(f"/v1/sites/{SITE}/fragments/{fid}", content=data[fid]).status_code == 202
            )
        _wait(
            browser,
            lambda d: _text(d, "result-status") == "closed" and set(_walls(d)) == set(ids),
            45,
            "the loop closes and every fragment is drawn",
        )
        closed = http.get(f"/v1/sites/{SITE}/result").json()
    _shot(browser, "02-closed.png")
    upload_note = browser.find_element(By.CSS_SELECTOR, f'#uploads li[data-upload="{ids[1]}"]').text
    assert "accepted" in upload_note, upload_note
    assert browser.execute_script("return window.__notReloaded === true;")
    confidence = float(_text(browser, "confidence"))
    assert confidence == pytest.approx(closed["confidence"], abs=0.006)
    rows = browser.find_elements(By.CSS_SELECTOR, "#fragments tbody tr")
    assert sorted(r.get_attribute("data-fragment") for r in rows) == sorted(ids)
    assert all(r.find_element(By.CSS_SELECTOR, ".state").text == "done" for r in rows)
    # One colour per id, the same as the service's pictures; labels at their walls.
    for fid, wall in _walls(browser).items():
        assert wall.get_attribute("stroke") == fragment_color(fid)
        assert _label_near_its_walls(browser, fid) < 30
    assert re.fullmatch(r"\d+(\.\d+)? m", _text(browser, "scale-text"))

    # An ambiguous result arrives: its alternatives can be switched, still without a reload.
    before = _walls(browser)[ids[0]].get_attribute("points")
    event = site_event("result", SITE, _ambiguous(closed), generation=99)
    redis_client.publish(Keys("fpj").site_channel(SITE), event)
    _wait(browser, lambda d: _text(d, "result-status") == "ambiguous", 10, "status ambiguous")
    buttons = browser.find_elements(By.CSS_SELECTOR, "#alternatives button")
    assert [b.text for b in buttons] == ["most probable (p = 0.60)", "alternative 1 (p = 0.30)"]
    buttons[1].click()
    _wait(
        browser,
        lambda d: _walls(d)[ids[0]].get_attribute("points") != before,
        5,
        "the alternative is drawn",
    )
    assert "alternative 1" in _text(browser, "plan-note")
    _shot(browser, "03-ambiguous-alternative.png")
    browser.find_elements(By.CSS_SELECTOR, "#alternatives button")[0].click()
    _wait(browser, lambda d: _walls(d)[ids[0]].get_attribute("points") == before, 5, "back")
    assert browser.execute_script("return window.__notReloaded === true;")
    assert time.monotonic() - started < 60


def test_sites_page_lists_sites(server: ApiServer, browser: Any) -> None:
    with server.client() as http:
        http.put(
            "/v1/sites/listed/fragments/a", content=encode_ply(small_scene().fragments[0].points)
        )
    browser.get(f"{server.url}/")
    _wait(
        browser,
        lambda d: d.find_elements(By.CSS_SELECTOR, '#sites tr[data-site="listed"]'),
        10,
        "the site is listed",
    )
    _shot(browser, "04-sites.png")
    link = browser.find_element(By.CSS_SELECTOR, '#sites tr[data-site="listed"] a')
    assert link.get_attribute("href") == f"{server.url}/sites/listed"


def test_docs_render_offline(server: ApiServer, browser: Any) -> None:
    browser.get(f"{server.url}/docs")
    _wait(
        browser,
        lambda d: d.find_elements(By.CSS_SELECTOR, ".opblock-summary-path"),
        15,
        "Swagger UI lists the operations",
    )
    paths = {
        e.text.replace("\u200b", "")
        for e in browser.find_elements(By.CSS_SELECTOR, ".opblock-summary-path")
    }
    assert "/v1/sites/{site_id}/fragments/{fragment_id}" in paths
    _shot(browser, "05-docs.png")


def test_a_scoped_token_sees_its_sites_only(
    redis_url: str, api_factory: Callable[..., ApiServer], browser: Any
) -> None:
    server = api_factory(make_settings(redis_url, tokens="admin,viewer:lab:read"))
    with server.client(headers={"Authorization": "Bearer admin"}) as http:
        for site in ("lab", "yard"):
            put = http.put(f"/v1/sites/{site}/fragments/a", content=ply_bytes(300))
            assert put.status_code == 202, put.text
    browser.get(f"{server.url}/?token=viewer")  # the page keeps the token
    _wait(
        browser,
        lambda d: d.find_elements(By.CSS_SELECTOR, '#sites tr[data-site="lab"]'),
        10,
        "the token's site is listed",
    )
    assert not browser.find_elements(By.CSS_SELECTOR, '#sites tr[data-site="yard"]')
    browser.get(f"{server.url}/sites/yard")
    _wait(
        browser,
        lambda d: "may not do that on this site" in _text(d, "token-note"),
        10,
        "the page says the token has no right on this site",
    )
    _shot(browser, "05-scoped-token.png")
