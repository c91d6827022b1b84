"""The live view in a real headless Chromium (Debian's chromium and chromium-driver, driven
through Selenium): during a 3-robot run the page shows the robots and at least one link
change, a click on a robot draws the routes to it, and a screenshot is kept as an artefact
(results/artefacts/live-view.png)."""

import json
import os
import shutil
import socket
import threading
import time
import uuid
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
ARTEFACTS = REPO / "results" / "artefacts"

pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason="needs root (network namespaces)")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    for tool in ("chromium", "chromedriver"):
        if shutil.which(tool) is None:
            pytest.fail(f"{tool} missing: `make browser-test` installs chromium-driver")
    opts = webdriver.ChromeOptions()
    opts.binary_location = shutil.which("chromium")
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=800,820"):  # fmt: skip
        opts.add_argument(arg)
    return webdriver.Chrome(service=Service(shutil.which("chromedriver")), options=opts)


def test_live_page_shows_robots_link_changes_and_routes(tmp_path):
    from testbed.run import RunConfig, run
    from topology.network import destroy

    port = free_port()
    name = "tv" + uuid.uuid4().hex[:6]
    cfg = RunConfig(robots=3, comm_range=5.0, laser_range=2.0, seed=5, time_scale=4.0,
                    routing="oracle", max_steps=3000, view=f"127.0.0.1:{port}")  # fmt: skip
    box = {}
    worker = threading.Thread(
        target=lambda: box.update(r=run(cfg, str(tmp_path / "run"), name, progress=False))
    )
    worker.start()
    driver = None
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                time.sleep(0.2)
        driver = browser()
        driver.get(f"http://127.0.0.1:{port}/")
        links_seen, frames = set(), 0
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and (len(links_seen) < 2 or frames < 20):
            body = driver.find_element("tag name", "body")
            frames = int(body.get_attribute("data-frames") or 0)
            links_seen.add(body.get_attribute("data-links"))
            time.sleep(0.2)
        assert frames >= 20, "the page got no frames"
        assert len(links_seen - {None}) >= 2, f"no link change seen: {links_seen}"
        assert "live: run" in driver.find_element("id", "title").text
        # Click robot 1 where the page draws it now (one script: the robot keeps moving).
        selected = driver.execute_script(
            "const p = run.positions[Number(slider.value)];"
            "const k = canvas.width / Math.max(...run.map_m);"
            "const r = canvas.getBoundingClientRect();"
            "canvas.dispatchEvent(new MouseEvent('click', {bubbles: true,"
            " clientX: r.left + 1 + p[0] * k, clientY: r.top + 1 + p[1] * k}));"
            "return document.body.dataset.selected;"
        )
        assert selected == "1"
        deadline = time.monotonic() + 10
        hops = None
        while time.monotonic() < deadline and not hops:
            hops = driver.find_element("tag name", "body").get_attribute("data-hops")
            time.sleep(0.2)
        assert hops is not None and set(json.loads(hops)) == {"2", "3"}
        ARTEFACTS.mkdir(parents=True, exist_ok=True)
        driver.save_screenshot(str(ARTEFACTS / "live-view.png"))
        assert (ARTEFACTS / "live-view.png").stat().st_size > 5000
    finally:
        if driver is not None:
            driver.quit()
        worker.join(timeout=180)
        destroy(name)
    assert box["r"]["status"] in ("complete", "step_cap")
