"""Headless Chromium driven by Playwright for Python, for the viewer's tests and the
README's screenshot: the system's browser (Debian's ``chromium``; ``make browser``
installs it), never a browser Playwright downloads.

A page opens from its ``file://`` URL with every other request aborted (the page must
need no network) and its console errors and page errors collected.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from ..errors import CassiError

#: Where the system's Chromium is looked for (CASSI_CHROMIUM names another).
CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome")
# SwiftShader's software WebGL: headless machines have no GPU.
CHROMIUM_ARGS = ("--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                 "--autoplay-policy=no-user-gesture-required")  # fmt: skip


def chromium_path() -> str | None:
    """The system's Chromium executable, or None."""
    given = os.environ.get("CASSI_CHROMIUM")
    if given:
        return given if Path(given).is_file() else None
    for name in CHROMIUM_NAMES:
        found = shutil.which(name)
        if found:
            return found
    return None


def browser_missing() -> str | None:
    """Why the browser tests cannot run here (one line), or None if they can."""
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "Playwright for Python is not installed (pip install -e '.[test]')"
    if chromium_path() is None:
        return "no Chromium on this machine (make browser installs Debian's chromium)"
    return None


@contextmanager
def chromium() -> Iterator[Any]:
    """A headless Chromium (a Playwright ``Browser``), closed on exit."""
    why = browser_missing()
    if why:
        raise CassiError(f"viewer: cannot start a browser: {why}")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium_path(), headless=True,
                                    args=list(CHROMIUM_ARGS))  # fmt: skip
        try:
            yield browser
        finally:
            browser.close()


def open_page(browser: Any, path: str | os.PathLike, *, size: tuple[int, int] = (1200, 900)
              ) -> tuple[Any, list[str]]:  # fmt: skip
    """Open the file ``path`` in a new page of ``browser`` at ``size`` (CSS pixels, device
    scale 1) with every request but the file's own aborted; wait until the viewer has
    started. Returns ``(page, errors)``: ``errors`` fills with the console's errors, the
    page's uncaught errors and the aborted requests' URLs as they come."""
    url = Path(path).resolve().as_uri()
    context = browser.new_context(viewport={"width": size[0], "height": size[1]},
                                  device_scale_factor=1)  # fmt: skip
    errors: list[str] = []

    def route(r):
        if r.request.url == url or r.request.url.startswith("data:"):
            r.continue_()
        else:
            errors.append(f"request blocked: {r.request.url}")
            r.abort()

    context.route("**/*", route)
    page = context.new_page()
    page.on("console", lambda m: errors.append(f"console: {m.text}") if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(f"page error: {e}"))
    page.goto(url)
    page.wait_for_function("window.cassiViewer !== undefined || "
                           "getComputedStyle(document.getElementById('cassi-nogl')).display "
                           "!== 'none'")  # fmt: skip
    return page, errors


def screenshot(html: str | os.PathLike, png: str | os.PathLike, *, frame: int | None = None,
               preset: str = "side", size: tuple[int, int] = (1200, 900)) -> Path:  # fmt: skip
    """A PNG of the whole viewer page ``html`` at data frame ``frame`` (default: the middle)
    in the camera preset ``preset``, taken in headless Chromium. Returns ``png``."""
    with chromium() as browser:
        page, errors = open_page(browser, html, size=size)
        page.evaluate("([f, p]) => { const v = window.cassiViewer; v.setPreset(p); "
                      "v.seekFrame(f === null ? Math.floor(v.n / 2) : f); }", [frame, preset])
        page.screenshot(path=str(png), full_page=True)
        if errors:
            raise CassiError(f"viewer: the page reported errors: {errors[:3]}")
    return Path(png)
