"""A real headless Chromium for the studio's page tests (Debian's ``chromium`` + ``chromium-driver``).

Where Chromium, its driver or the ``selenium`` package is missing the tests skip with one line;
CI sets ``CONTROLMM_REQUIRE_BROWSER=1`` (``.ci/run``, which also installs the packages), which turns
that skip into a failure.
"""

from __future__ import annotations

import io
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pytest
from PIL import Image

CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--window-size=1400,1000",
)


def _find(names: tuple[str, ...]) -> str | None:
    for name in names:
        path = shutil.which(name) or (f"/usr/bin/{name}" if os.path.exists(f"/usr/bin/{name}") else None)
        if path:
            return path
    return None


def browser_or_skip() -> tuple[str, str]:
    """Paths of Chromium and chromedriver, or a skip (a failure under CONTROLMM_REQUIRE_BROWSER=1)."""
    chromium = _find(("chromium", "chromium-browser"))
    driver = _find(("chromedriver",))
    missing = []
    try:
        import selenium  # noqa: F401 - only checked for: the tests drive Chromium with it
    except ImportError:
        missing.append("the selenium package (pip install -e '.[test]')")
    if chromium is None:
        missing.append("Chromium (apt-get install chromium)")
    if driver is None:
        missing.append("chromedriver (apt-get install chromium-driver)")
    if missing:
        reason = f"browser tests need {' and '.join(missing)}"
        if os.environ.get("CONTROLMM_REQUIRE_BROWSER") == "1":
            pytest.fail(reason)
        pytest.skip(reason)
    assert chromium is not None and driver is not None
    return chromium, driver


@contextmanager
def headless_chromium() -> Iterator:
    """A selenium WebDriver on a fresh headless Chromium profile (removed afterwards)."""
    chromium, driver = browser_or_skip()
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    profile = tempfile.mkdtemp(prefix="controlmm-chromium-")
    options = webdriver.ChromeOptions()
    options.binary_location = chromium
    for flag in (*CHROMIUM_FLAGS, f"--user-data-dir={profile}"):
        options.add_argument(flag)
    browser = webdriver.Chrome(service=Service(executable_path=driver), options=options)
    try:
        yield browser
    finally:
        browser.quit()
        shutil.rmtree(profile, ignore_errors=True)


def element_pixels(browser, element_id: str) -> np.ndarray:
    """(H, W, 3) uint8 pixels of a page element, from a real screenshot."""
    png = browser.get_screenshot_as_png()
    image = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
    rect = browser.execute_script(
        "const r = document.getElementById(arguments[0]).getBoundingClientRect();"
        "return [r.left, r.top, r.width, r.height, window.devicePixelRatio || 1];",
        element_id,
    )
    x, y, w, h, dpr = (float(v) for v in rect)
    return image[int(y * dpr) : int((y + h) * dpr), int(x * dpr) : int((x + w) * dpr)]
