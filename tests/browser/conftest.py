"""Fixtures for browser tests: Debian's headless Chromium driven by Playwright (sync API) against viser servers.

Chromium draws with software WebGL here, and a drag redraws the whole cell: tests that are not about the arm start
the app with `serve(simple_arm=True)` (the arm as links and joints, `rrbc view --simple-arm`), which the UR5's meshes
otherwise dominate; the arm's own test, the VEC tab's and the lesson's (whose points must not be hidden behind the
arm) draw the meshes. Every test of the app but the arm's also starts it with
`plain_light=True` (`rrbc view --plain-light`): the environment map's image-based lighting was most of the work of
Chromium's GPU process at each page load and each frame (measured once by hand), which starved the other pytest
worker; the arm's test holds that the default lighting has the map. Contexts come from
`helpers.new_context` (the render heartbeat at 5 s, helpers.QUIET_HEARTBEAT_SCRIPT).

Chromium comes from `bash scripts/setup.sh --browser` (never `playwright install`). Every test here is marked
``browser``; deselect them with ``-m "not browser"``.

    chromium_path   session   "/usr/bin/chromium"; FAILS (does not skip) if it is missing
    browser         session   playwright Browser (headless, flags from helpers.CHROMIUM_ARGS)
    browser_context function  fresh BrowserContext (helpers.new_context: 1280x800, the render heartbeat at 5 s);
                              closed (tabs disconnect) at teardown
    viser_app       function  viser_app(factory) -> app: calls factory() (zero-arg, returns an object with .port
                              and .stop(), e.g. helpers.start_demo_app or lambda: rrbc_viz.serve.serve()), waits for
                              its port, stops it at teardown
    page_for        function  page_for(url, *, timeout_s=30, dismiss_notification=True, wait=True, init_script=None)
                              -> (page, requests): new tab in browser_context, every request and websocket URL
                              recorded in `requests` (a live list); returns once the viser client is connected
                              (websocket messages received, __viserMutable mounted, no "Connecting...") and the
                              "Software WebGL rendering detected" notification is closed. wait=False returns right
                              after the document loads. init_script: JavaScript run in the page before its own
                              scripts (e.g. helpers.UNDRAWN_TAB_SCRIPT).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from . import helpers

_HERE = Path(__file__).resolve().parent


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "browser: drives headless Chromium (needs `scripts/setup.sh --browser`)")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if _HERE in Path(str(item.fspath)).resolve().parents:
            item.add_marker(pytest.mark.browser)
            # under pytest-xdist (scripts/test.sh: -n 2 --dist loadgroup) every browser test runs on one worker: one
            # Chromium and one software-WebGL page drawing at a time, the session's browser shared by all of them
            item.add_marker(pytest.mark.xdist_group("browser"))


@pytest.fixture(scope="session")
def chromium_path() -> str:
    path = helpers.CHROMIUM_PATH
    if not (os.path.isfile(path) and os.access(path, os.X_OK)):
        pytest.fail(
            f"{path} is missing: browser tests need Debian's chromium. Install it with "
            "`bash scripts/setup.sh --browser` (scripts/test.sh and CI do this); do NOT run `playwright install`.",
            pytrace=False,
        )
    return path


@pytest.fixture(scope="session")
def browser(chromium_path: str):
    from playwright.sync_api import sync_playwright

    pw = sync_playwright().start()
    try:
        b = helpers.launch_chromium(pw, executable_path=chromium_path)
    except Exception:
        pw.stop()
        raise
    yield b
    try:
        b.close()
    finally:
        pw.stop()


@pytest.fixture
def browser_context(browser):
    ctx = helpers.new_context(browser)
    ctx.set_default_timeout(30_000)
    yield ctx
    ctx.close()


@pytest.fixture
def viser_app(request: pytest.FixtureRequest) -> Callable[[Callable[[], Any]], Any]:
    apps: list[Any] = []

    def start(factory: Callable[[], Any], timeout_s: float = 30.0) -> Any:
        app = factory()
        apps.append(app)
        helpers.wait_for_port(int(app.port), timeout_s=timeout_s)
        return app

    def stop_all() -> None:
        for app in reversed(apps):
            try:
                app.stop()
            except Exception:  # noqa: BLE001 - teardown: keep stopping the others
                pass

    request.addfinalizer(stop_all)
    return start


@pytest.fixture
def page_for(browser_context) -> Callable[..., tuple[Any, list[str]]]:
    def open_page(
        url: str,
        *,
        timeout_s: float = 30.0,
        dismiss_notification: bool = True,
        wait: bool = True,
        init_script: str | None = None,
    ) -> tuple[Any, list[str]]:
        page = browser_context.new_page()
        if init_script:
            page.add_init_script(init_script)
        requests: list[str] = []
        frames_received = [0]

        def on_websocket(ws: Any) -> None:
            requests.append(ws.url)
            ws.on("framereceived", lambda _payload: frames_received.__setitem__(0, frames_received[0] + 1))

        # Listeners first, so the document request itself is recorded.
        page.on("request", lambda req: requests.append(req.url))
        page.on("websocket", on_websocket)
        t0 = time.monotonic()
        page.goto(url, wait_until="domcontentloaded", timeout=timeout_s * 1000)
        if not wait:  # caller waits (e.g. opening several tabs that connect concurrently)
            return page, requests
        remaining = lambda: max(1.0, timeout_s - (time.monotonic() - t0))
        # The client shows "Inactive" before it first connects, so "no 'Connecting'" alone proves nothing: also
        # require the websocket to have delivered the server's initial messages.
        helpers.wait_for(
            lambda: frames_received[0] > 0, remaining(), message=f"websocket messages from {url}", page=page
        )
        helpers.wait_client_ready(page, remaining())
        if dismiss_notification:
            helpers.dismiss_software_webgl_notification(page, timeout_s=1.0)
        return page, requests

    return open_page
