"""The view in a real headless Chromium (Debian's chromium and chromium-driver, driven
through Selenium): the live view of a 3-robot run on the office map, the replay of that run,
the view of a network brought up by hand (`net up --view`) and the sweep's report.html.

Each test keeps a screenshot under results/artefacts/ (its path is printed) for a person to
look at, and checks what a screenshot alone would not prove: the page asked for nothing that
is not there (no 404 in the browser's console), the header counts the links it draws, no
"?" or "null" stands where a number should, and every robot is drawn whole inside the
canvas.
"""

import json
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
ARTEFACTS = REPO / "results" / "artefacts"
OFFICE = REPO / "testbed" / "experiments" / "maps" / "office.png"
TESTBED = [sys.executable, "-m", "testbed.cli"]

pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason="needs root (network namespaces)")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_listening(port: int, timeout: float = 60) -> None:
    deadline = time.monotonic() + timeout
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return
        except OSError:
            assert time.monotonic() < deadline, f"nothing listens on port {port}"
            time.sleep(0.2)


def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    for tool in ("chromium", "chromedriver"):
        if shutil.which(tool) is None:
            pytest.fail(f"{tool} missing: `make browser-test` installs chromium-driver")
    opts = webdriver.ChromeOptions()
    opts.binary_location = shutil.which("chromium")
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1060,1000", "--hide-scrollbars"):  # fmt: skip
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(shutil.which("chromedriver")), options=opts)


def keep_screenshot(driver, name: str, whole_page: bool = False) -> Path:
    ARTEFACTS.mkdir(parents=True, exist_ok=True)
    path = ARTEFACTS / name
    if whole_page:  # the window as tall as the page (up to 6000 px): one picture of it all
        height = driver.execute_script("return document.documentElement.scrollHeight")
        driver.set_window_size(1060, min(6000, height + 40))
    driver.save_screenshot(str(path))
    assert path.stat().st_size > 5000
    print(f"screenshot: {path}")
    return path


def console_errors(driver) -> list[str]:
    """What failed to load or threw, as the browser's console reports it."""
    return [e["message"] for e in driver.get_log("browser") if e["level"] == "SEVERE"]


def body(driver, attr: str):
    return driver.find_element("tag name", "body").get_attribute(attr)


def check_drawn_page(driver) -> None:
    """What the header says matches what is drawn; every robot is whole on the canvas. The
    header and the drawing are read in one script: a live page may take its next step between
    two reads (a loaded machine showed "2 links" in the header read first and 1 link drawn at
    the step after)."""
    drawn = driver.execute_script(
        "const s = Number(slider.value), pos = run.positions[s];"
        "const pts = [];"
        "for (let r = 0; r < run.robots; r++) pts.push(toCanvas(pos[2 * r], pos[2 * r + 1]));"
        "return {pts: pts, links: drawnLinks(s).length, w: canvas.width, h: canvas.height,"
        "        header: document.getElementById('counters').textContent};"
    )
    header = drawn["header"]
    assert "?" not in header and "null" not in header and "undefined" not in header, header
    n = drawn["links"]
    assert f"{n} link{'' if n == 1 else 's'}," in header, (header, n)
    for x, y in drawn["pts"]:  # a robot's dot is 6 px round: all of it inside
        assert 6 <= x <= drawn["w"] - 6 and 6 <= y <= drawn["h"] - 6, drawn["pts"]


@pytest.fixture(scope="module")
def live_run(tmp_path_factory):
    """A 3-robot run on the office map with --view, and the browser on its page while it
    runs. Yields (driver, port, run directory, box with the result once the run is over)."""
    from testbed.run.execute import RunConfig, run
    from topology.network import destroy

    out = tmp_path_factory.mktemp("live") / "run"
    port = free_port()
    name = "tv" + uuid.uuid4().hex[:6]
    cfg = RunConfig(robots=3, comm_range=5.0, laser_range=2.0, seed=5, time_scale=4.0,
                    routing="oracle", max_steps=3000, map=str(OFFICE),
                    view=f"127.0.0.1:{port}")  # fmt: skip
    box = {}
    worker = threading.Thread(
        target=lambda: box.update(r=run(cfg, str(out), name, progress=False).to_json())
    )
    worker.start()
    driver = None
    try:
        wait_listening(port)
        driver = browser()
        driver.get(f"http://127.0.0.1:{port}/")
        yield driver, port, out, box, worker
    finally:
        if driver is not None:
            driver.quit()
        worker.join(timeout=300)
        destroy(name)


def test_live_page_shows_robots_link_changes_and_routes(live_run):
    driver, _port, _out, _box, _worker = live_run
    links_seen, frames = set(), 0
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline and (len(links_seen) < 2 or frames < 20):
        frames = int(body(driver, "data-frames") or 0)
        links_seen.add(body(driver, "data-links"))
        time.sleep(0.2)
    assert frames >= 20, "the page got no frames"
    assert len(links_seen - {None}) >= 2, f"no link change seen: {links_seen}"
    assert "live: run" in driver.find_element("id", "title").text
    # Click robot 1 where the page draws it now (one script: the robot keeps moving).
    selected = driver.execute_script(
        "const p = run.positions[Number(slider.value)];"
        "const [x, y] = toCanvas(p[0], p[1]);"
        "const r = canvas.getBoundingClientRect();"
        "canvas.dispatchEvent(new MouseEvent('click', {bubbles: true,"
        " clientX: r.left + 1 + x, clientY: r.top + 1 + y}));"
        "return document.body.dataset.selected;"
    )
    assert selected == "1"
    deadline = time.monotonic() + 10
    hops = None
    while time.monotonic() < deadline and not hops:
        hops = body(driver, "data-hops")
        time.sleep(0.2)
    assert hops is not None and set(json.loads(hops)) == {"2", "3"}
    # Until the display robot saved a snapshot: the panel beside the map shows it.
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not driver.execute_script(
        "return snapImg.complete && snapImg.naturalWidth > 0"
    ):
        time.sleep(0.5)
    assert driver.find_element("id", "display").is_displayed(), "no display snapshot shown"
    check_drawn_page(driver)
    keep_screenshot(driver, "live-view.png")
    assert console_errors(driver) == []


def test_replay_of_the_run_draws_its_last_step(live_run):
    driver, _port, out, box, worker = live_run
    worker.join(timeout=300)
    assert box["r"]["status"] in ("complete", "step_cap")
    port = free_port()
    server = subprocess.Popen([*TESTBED, "view", str(out), "--view", f"127.0.0.1:{port}"],
                              cwd=REPO, stdout=subprocess.DEVNULL)  # fmt: skip
    try:
        wait_listening(port)
        driver.get_log("browser")  # the live page's console is not this page's
        driver.get(f"http://127.0.0.1:{port}/")
        deadline = time.monotonic() + 30
        while body(driver, "data-ready") != "1":
            assert time.monotonic() < deadline, "the replay page did not load"
            time.sleep(0.2)
        assert "replay: run" in driver.find_element("id", "title").text
        driver.execute_script(
            "slider.value = slider.max; slider.dispatchEvent(new Event('input'));"
        )
        deadline = time.monotonic() + 10
        while not driver.find_element("id", "display").is_displayed():
            assert time.monotonic() < deadline, "no display snapshot in the replay"
            time.sleep(0.2)
        time.sleep(0.5)  # the map's and the snapshot's pictures
        check_drawn_page(driver)
        assert "coverage" in driver.find_element("id", "counters").text
        keep_screenshot(driver, "replay.png")
        assert console_errors(driver) == []
    finally:
        server.terminate()
        server.wait(timeout=10)


def test_net_up_view_draws_robots_on_the_edge_whole(tmp_path):
    name = "tv" + uuid.uuid4().hex[:6]
    port = free_port()
    run = dict(cwd=REPO, capture_output=True, text=True)
    up = subprocess.run([*TESTBED, "net", "up", name, "--robots", "5", "--layout", "chain",
                         "--spacing", "8", "--comm-range", "10", "--routing", "oracle",
                         "--time-scale", "5", "--view", str(port)], **run)  # fmt: skip
    assert up.returncode == 0, up.stderr
    driver = None
    try:
        wait_listening(port)
        # r5 walks below the start: the drawn area grows to hold it, range ring and all.
        moved = subprocess.run([*TESTBED, "net", "move", name, "r5", "30", "-6"], **run)
        assert moved.returncode == 0, moved.stderr
        driver = browser()
        driver.get(f"http://127.0.0.1:{port}/")
        deadline = time.monotonic() + 30
        while not driver.execute_script(
            "return run && run.positions.length > 0 && run.positions.at(-1)[9] === -6"
        ):
            assert time.monotonic() < deadline, "the view never showed the move"
            time.sleep(0.2)
        time.sleep(0.3)
        header = driver.find_element("id", "counters").text
        assert "coverage" not in header and "time scale 5" in header, header
        assert "4 links" in header, header
        check_drawn_page(driver)
        keep_screenshot(driver, "net-up-view.png")
        assert console_errors(driver) == []
    finally:
        if driver is not None:
            driver.quit()
        subprocess.run([*TESTBED, "net", "down", name], **run)


def test_report_html_renders_with_its_figures(tmp_path):
    """report.html of a (synthetic) sweep, opened from disk as a reader would."""
    from testbed.analysis import report
    from testbed.sweep import file as sweepfile
    from tests.unit.test_sweep_synthetic import make_sweep

    spec = sweepfile.SweepSpec.of(robots=(1, 2, 3), comm_range=(5.0,), laser_range=(2.0,), runs=2)
    make_sweep(tmp_path, spec)
    report.write_report(tmp_path, metrics_of=lambda run: None)
    driver = browser()
    try:
        driver.get((tmp_path / "report.html").as_uri())
        images = driver.execute_script(
            "return [...document.images].map(i => [i.naturalWidth, i.complete]);"
        )
        assert images and all(w > 0 and done for w, done in images), images
        keep_screenshot(driver, "report-html.png", whole_page=True)
        assert console_errors(driver) == []
    finally:
        driver.quit()


def test_net_up_view_on_the_office_map_draws_its_walls(tmp_path):
    """`net up --range-model los --map PNG --view`: the map's picture under the robots (it
    once failed to start: the view process died before it served anything)."""
    name = "tv" + uuid.uuid4().hex[:6]
    port = free_port()
    run = dict(cwd=REPO, capture_output=True, text=True)
    up = subprocess.run([*TESTBED, "net", "up", name, "--robots", "3", "--positions",
                         "2.5,5 7.5,5 2.5,10", "--comm-range", "8", "--range-model", "los",
                         "--map", str(OFFICE), "--view", str(port)], **run)  # fmt: skip
    assert up.returncode == 0, up.stderr
    driver = None
    try:
        wait_listening(port, timeout=20)
        driver = browser()
        driver.get(f"http://127.0.0.1:{port}/")
        deadline = time.monotonic() + 30
        while not driver.execute_script("return mapImg !== null && run.positions.length > 0"):
            assert time.monotonic() < deadline, "no map picture or no frame"
            time.sleep(0.2)
        time.sleep(0.3)
        assert driver.execute_script("return run.map_img_m") == [20.0, 20.0]
        assert "1 link," in driver.find_element("id", "counters").text  # r1-r3, not r1-r2
        check_drawn_page(driver)
        keep_screenshot(driver, "net-up-office-view.png")
        assert console_errors(driver) == []
    finally:
        if driver is not None:
            driver.quit()
        subprocess.run([*TESTBED, "net", "down", name], **run)
