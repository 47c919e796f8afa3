"""The page in a real browser: headless Chromium (Debian packages ``chromium`` and
``chromium-driver``, which `make test` installs with apt-get when it can) opens the file,
runs MeshCat's viewer without console errors, draws the scene (the canvas is not one
colour), and the time slider moves the robot (the pictures at the start and at the
exchange differ) and names the phase.  When Chromium is missing the test installs it as
root with apt-get, as `make test` does; it is skipped, saying why, only where that fails."""

from __future__ import annotations

import importlib.util
import io
import os
import shutil
import subprocess

import numpy as np
import pytest
from PIL import Image

from regrasp_cli.manip.modes import Kind
from regrasp_cli.show.geometry import robot_links

# --headless --no-sandbox --disable-gpu as asked; software WebGL (SwiftShader) must then be
# opted into on recent Chromium (the automatic fallback is deprecated); the small /dev/shm
# of containers is avoided.
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
                  "--disable-dev-shm-usage", "--window-size=1280,800")
READY_S = 60  # s for the page to load and start
INSTALL_S = 600  # s for apt-get


def _paths() -> tuple[str | None, str | None]:
    browser = next((shutil.which(n) for n in ("chromium", "chromium-browser") if shutil.which(n)), None)
    return browser, shutil.which("chromedriver")


def _install() -> str | None:
    """Install Debian's chromium and chromium-driver (as `make test` does); None when done,
    else why not."""
    if os.name != "posix" or os.geteuid() != 0:
        return "not root"
    if not shutil.which("apt-get"):
        return "no apt-get"
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    for cmd in (["apt-get", "update", "-qq"], ["apt-get", "install", "-y", "-qq", "chromium", "chromium-driver"]):
        try:
            done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=INSTALL_S)
        except subprocess.TimeoutExpired:
            return f"`{' '.join(cmd)}` took more than {INSTALL_S} s"
        if done.returncode:
            last = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["no output"]
            return f"`{' '.join(cmd)}` failed: {last[0]}"
    return None


def _chromium() -> tuple[str, str]:
    if importlib.util.find_spec("selenium") is None:
        pytest.skip("Chromium not usable here: the selenium package is missing (pip install -e '.[dev]')")
    browser, driver = _paths()
    if not (browser and driver):
        why = _install()
        browser, driver = _paths()
        if not (browser and driver):
            missing = " and ".join(n for n, p in (("chromium", browser), ("chromedriver", driver)) if not p)
            pytest.skip(f"Chromium not installable here: {missing} missing, and the Debian packages chromium and "
                        f"chromium-driver could not be installed ({why or 'not on PATH after installing'})")
    return browser, driver


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
    handover = next(p for p in view.plan.phases if p.kind == Kind.HANDOVER)  # the taker closes: close_left
    seek(browser, float(handover.times[-1]) - 0.01)
    exchange = canvas_middle(browser)
    assert browser.execute_script("return document.getElementById('phase').textContent").endswith(handover.name)

    severe = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert not severe, severe
    flat = start.reshape(-1, 3)
    assert flat.std(axis=0).max() > 20 and len(np.unique(flat, axis=0)) > 100, "the canvas is blank"
    assert (np.abs(start - exchange).max(axis=2) > 30).mean() > 0.005, "the slider does not move the robot"
