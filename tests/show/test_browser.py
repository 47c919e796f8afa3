"""The page in a real browser: headless Chromium (Debian packages ``chromium`` and
``chromium-driver``, which `make test` installs with apt-get when it can) opens the file,
runs MeshCat's viewer without console errors, draws the scene (the canvas is not one
colour), and the time slider moves the robot (the pictures at the start and at the
exchange differ) and names the phase.  Skipped, saying why, only where Chromium is not
installed."""

from __future__ import annotations

import io
import os
import shutil

import numpy as np
import pytest
from PIL import Image

from regrasp_cli.show.geometry import robot_links

# --headless --no-sandbox --disable-gpu as asked; software WebGL (SwiftShader) must then be
# opted into on recent Chromium (the automatic fallback is deprecated); the small /dev/shm
# of containers is avoided.
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
                  "--disable-dev-shm-usage", "--window-size=1280,800")
READY_S = 60


def _chromium() -> tuple[str, str]:
    try:
        import selenium  # noqa: F401
    except ImportError:
        pytest.skip("Chromium not usable here: the selenium package is missing (pip install -e '.[dev]')")
    browser = next((shutil.which(n) for n in ("chromium", "chromium-browser") if shutil.which(n)), None)
    driver = shutil.which("chromedriver")
    if browser and driver:
        return browser, driver
    why = []
    if os.name == "posix" and os.geteuid() != 0:
        why.append("not root")
    if not shutil.which("apt-get"):
        why.append("no apt-get")
    missing = " and ".join(n for n, p in (("chromium", browser), ("chromedriver", driver)) if not p)
    pytest.skip(f"Chromium not installable here: {missing} not on PATH ({', '.join(why) or 'apt-get failed'}; "
                "`make test` installs the Debian packages chromium and chromium-driver when run as root)")


@pytest.fixture(scope="module")
def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    binary, driver = _chromium()
    options = Options()
    options.binary_location = binary
    for flag in CHROMIUM_FLAGS:
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    d = webdriver.Chrome(service=Service(driver), options=options)
    try:
        yield d
    finally:
        d.quit()


def canvas_middle(browser) -> np.ndarray:
    """The middle of the canvas (RGB): clear of the page's overlays at the top and bottom."""
    from selenium.webdriver.common.by import By

    canvas = browser.find_element(By.TAG_NAME, "canvas")
    img = np.asarray(Image.open(io.BytesIO(canvas.screenshot_as_png)).convert("RGB"), dtype=float)
    h, w = img.shape[:2]
    return img[h // 6: h * 3 // 4, w // 6: w * 5 // 6]


def seek(browser, t: float) -> None:
    """Move the page's time slider to t (s), as a user drags it, and let it render."""
    browser.execute_script(
        "const s = document.getElementById('time'); s.value = arguments[0];"
        "s.dispatchEvent(new Event('input'));", t)
    browser.execute_script("return new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)));")


def test_the_page_runs_in_chromium(browser, shown, view):
    from selenium.webdriver.support.ui import WebDriverWait

    result, page, _ = shown
    assert result.exit_code == 0, (result.output, result.exception)
    browser.get(page.resolve().as_uri())
    WebDriverWait(browser, READY_S).until(lambda d: d.execute_script(
        "return !!(window.viewer && viewer.animator && viewer.animator.actions.length > 0)"))
    n_actions, duration = browser.execute_script("return [viewer.animator.actions.length, viewer.animator.duration]")
    assert n_actions == len(robot_links(view.inputs.robot)) + 1  # every link with geometry, and the object
    assert duration == pytest.approx(view.duration, abs=1e-3)

    seek(browser, 0.0)
    start = canvas_middle(browser)
    assert browser.execute_script("return viewer.renderer.info.render.triangles") > 1000
    t_exchange = next(float(p.times[-1]) for p in view.plan.phases if p.name == "close_left")
    seek(browser, t_exchange - 0.01)
    exchange = canvas_middle(browser)
    assert browser.execute_script("return document.getElementById('phase').textContent").endswith("close_left")

    severe = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert not severe, severe
    flat = start.reshape(-1, 3)
    assert flat.std(axis=0).max() > 20 and len(np.unique(flat, axis=0)) > 100, "the canvas is blank"
    assert (np.abs(start - exchange).max(axis=2) > 30).mean() > 0.005, "the slider does not move the robot"
