"""The live web viewer: its page in headless Chromium (Debian's package) shows the robot and
the status, update() is cheap, the package does not import viser, and the demo runs.

Chromium is driven over the DevTools protocol (a websocket on 127.0.0.1) so that the test
waits on conditions (the status in the DOM, the robot in the picture) instead of fixed
sleeps. Host names other than 127.0.0.1 do not resolve in that browser, so it reaches no other
machine.
"""

from __future__ import annotations

import base64
import io
import json
import os
import queue
import shutil
import signal
import subprocess
import sys
import threading
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from quaddance.errors import QuaddanceError
from quaddance.live.viewer import (
    DetectedBeat,
    LiveStatus,
    beat_list_markdown,
    beat_plot_data,
    check_listen_address,
    displayable_model,
    status_html,
    viewer_urls,
)

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
VIEWPORT_PX = (960, 640)
PAGE_TIMEOUT_S = 40.0


# -- pure helpers (no server) -----------------------------------------------------------------


def test_status_html_shows_tempo_lock_move_and_escapes() -> None:
    text = status_html(LiveStatus(128.04, True, "<b>kick</b>", 12.34))
    assert "128.0 BPM" in text and "LOCKED" in text and "12.3 s" in text
    assert "&lt;b&gt;kick&lt;/b&gt;" in text and "<b>kick</b>" not in text
    idle = status_html(LiveStatus())
    assert "-- BPM" in idle and "searching" in idle


def test_beat_plot_and_list() -> None:
    beats = [DetectedBeat(1.0, True), DetectedBeat(1.5, False), DetectedBeat(2.0, False)]
    t_s, bpm = beat_plot_data(beats)
    np.testing.assert_allclose(t_s, [1.5, 2.0])  # the first beat has no interval before it
    np.testing.assert_allclose(bpm, [120.0, 120.0])
    assert all(len(a) == 0 for a in beat_plot_data(beats[:1]))
    listing = beat_list_markdown(beats)
    assert listing.index("2.00 s") < listing.index("1.00 s **downbeat**")


def test_listen_address_is_checked_before_viser_starts() -> None:
    check_listen_address("127.0.0.1", 0)
    with pytest.raises(QuaddanceError, match="port 70000"):
        check_listen_address("127.0.0.1", 70000)


def test_a_physics_model_still_shows_the_robot() -> None:
    from quaddance.sim.scene import SceneCfg, build_model

    # visual=False has collision shapes only, in a group viewers hide: they are shown instead.
    shown = displayable_model(build_model(SceneCfg(), visual=False))
    assert np.any((shown.geom_bodyid > 0) & (shown.geom_group == 2))
    meshes = build_model(SceneCfg(), visual=True)
    np.testing.assert_array_equal(displayable_model(meshes).geom_group, meshes.geom_group)


def test_urls_for_a_wildcard_host_name_this_machine() -> None:
    assert viewer_urls("127.0.0.1", 8080) == ["http://127.0.0.1:8080"]
    assert viewer_urls("::1", 9000) == ["http://[::1]:9000"]
    wild = viewer_urls("0.0.0.0", 8080)
    assert wild[0] == "http://127.0.0.1:8080" and len(wild) == 2


def test_package_does_not_import_viser() -> None:
    code = (
        "import sys, quaddance.live, quaddance.live.viewer; "
        "sys.exit(int(any(m.split('.')[0] in ('viser', 'mjviser') for m in sys.modules)))"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)


# -- a running viewer -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def viewer() -> Iterator[Any]:
    from quaddance.live.viewer import LiveViewer
    from quaddance.sim.scene import SceneCfg, build_model

    live = LiveViewer(build_model(SceneCfg(), visual=True), host="127.0.0.1", port=0)
    yield live
    live.close()


def test_update_is_cheap_and_checks_its_input(viewer: Any) -> None:
    qpos = viewer.home_qpos()
    cost_s = []
    for i in range(500):
        qpos[7] = 0.1 * np.sin(i / 10)
        start = time.perf_counter()
        viewer.update(qpos)
        cost_s.append(time.perf_counter() - start)
        if i % 10 == 0:
            time.sleep(0.02)  # let the worker render some of them, as in a real loop
    cost_ms = np.array(cost_s) * 1e3
    print(f"update(): median {np.median(cost_ms):.4f} ms, p99 {np.percentile(cost_ms, 99):.4f} ms")
    assert np.median(cost_ms) < 0.5 and np.percentile(cost_ms, 99) < 5.0
    with pytest.raises(ValueError, match="shape"):
        viewer.update(qpos[:7])
    viewer.update(np.full_like(qpos, np.nan))  # skipped by the worker, not an error
    viewer.set_status(None, False, "-", 0.0)
    time.sleep(0.1)
    viewer.update(qpos)


class DevToolsError(RuntimeError):
    """An error answer from the browser (e.g. while the page is still being replaced)."""


class _DevTools:
    """Headless Chromium with a DevTools websocket on 127.0.0.1 (an OS-chosen port)."""

    def __init__(self, profile_dir: Path) -> None:
        import websockets.sync.client

        args = [
            str(CHROMIUM),
            "--headless",
            "--no-sandbox",  # CI runs as root
            "--use-gl=swiftshader",
            "--enable-unsafe-swiftshader",
            "--disable-dev-shm-usage",  # containers often have a small /dev/shm
            f"--window-size={VIEWPORT_PX[0]},{VIEWPORT_PX[1]}",
            "--remote-debugging-address=127.0.0.1",
            "--remote-debugging-port=0",
            f"--user-data-dir={profile_dir}",
            # Nothing outside this machine: no background services, no other host names.
            "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
            "--no-proxy-server",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--disable-default-apps",
            "--no-first-run",
            "--no-default-browser-check",
            "--mute-audio",
            "--hide-scrollbars",
            "about:blank",
        ]
        self._proc = subprocess.Popen(
            args,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,  # its own process group: closed with its helpers
        )
        self._lines: queue.Queue[str] = queue.Queue()
        self._stderr_tail: list[str] = []
        # Read stderr to the end on a thread: the DevTools address is there, and a full pipe
        # would stall the browser.
        threading.Thread(target=self._drain, daemon=True).start()
        try:
            port = self._devtools_port()
            # No proxy from the environment, here or below: straight to 127.0.0.1.
            direct = urllib.request.build_opener(urllib.request.ProxyHandler({}))
            with direct.open(f"http://127.0.0.1:{port}/json/list", timeout=10) as resp:
                pages = [t for t in json.load(resp) if t["type"] == "page"]
            self._ws = websockets.sync.client.connect(
                pages[0]["webSocketDebuggerUrl"],
                max_size=64 * 1024 * 1024,
                open_timeout=10,
                proxy=None,
            )
        except BaseException:
            self._stop_browser()
            raise
        self._next_id = 0

    def _drain(self) -> None:
        assert self._proc.stderr is not None
        for line in self._proc.stderr:
            self._lines.put(line)
            self._stderr_tail = [*self._stderr_tail[-19:], line]

    def _devtools_port(self) -> int:
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            try:
                line = self._lines.get(timeout=0.5)
            except queue.Empty:
                if self._proc.poll() is not None:
                    break
                continue
            if "DevTools listening on ws://" in line:
                return int(line.split("ws://127.0.0.1:")[1].split("/")[0])
        tail = "".join(self._stderr_tail)
        raise RuntimeError(f"chromium gave no DevTools address (exit {self._proc.poll()}):\n{tail}")

    def call(self, method: str, **params: Any) -> dict[str, Any]:
        self._next_id += 1
        self._ws.send(json.dumps({"id": self._next_id, "method": method, "params": params}))
        while True:  # events come in between; the answer carries our id
            message = json.loads(self._ws.recv(timeout=PAGE_TIMEOUT_S))
            if message.get("id") == self._next_id:
                if "error" in message:
                    raise DevToolsError(f"{method}: {message['error']}")
                return message["result"]

    def evaluate(self, expression: str) -> Any:
        result = self.call("Runtime.evaluate", expression=expression, returnByValue=True)
        return result["result"].get("value")

    def screenshot(self) -> np.ndarray:
        from PIL import Image

        png = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
        return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(np.int16)

    def close(self) -> None:
        try:
            self._ws.close()
        finally:
            self._stop_browser()

    def _stop_browser(self) -> None:
        if self._proc.poll() is None:
            os.killpg(self._proc.pid, signal.SIGTERM)
        try:
            self._proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            os.killpg(self._proc.pid, signal.SIGKILL)
            self._proc.wait(timeout=10)


def _robot_fraction(image: np.ndarray) -> float:
    """The share of dark, grey pixels where the camera looks, left of the control panel.

    The Go1 and its shadow are the only dark things there: the floor, the sky and the beat
    disc under the robot are light or bluish.
    """
    h, w = image.shape[:2]
    middle = image[int(0.25 * h) : int(0.9 * h), int(0.33 * w) : int(0.62 * w)]
    brightest, dullest = middle.max(axis=-1), middle.min(axis=-1)
    return float(np.mean((brightest < 100) & (brightest - dullest < 40)))


def _wait_for(condition: Any, what: str, timeout_s: float = PAGE_TIMEOUT_S) -> Any:
    deadline = time.monotonic() + timeout_s
    last_error = ""
    while time.monotonic() < deadline:
        try:
            value = condition()
        except DevToolsError as exc:  # the page is loading: ask again
            last_error, value = f" (last: {exc})", None
        if value is not None and value is not False:
            return value
        time.sleep(0.25)
    raise AssertionError(f"timed out after {timeout_s:.0f} s waiting for {what}{last_error}")


@pytest.mark.skipif(
    CHROMIUM is None, reason="chromium is not installed (scripts/setup.sh installs it)"
)
def test_page_shows_robot_and_status_in_headless_chromium(viewer: Any, tmp_path: Path) -> None:
    start_s = time.monotonic()
    home = viewer.home_qpos()
    viewer.update(home)
    viewer.set_status(123.4, True, "test-move", 7.5)
    viewer.beat(7.25, downbeat=True)

    browser = _DevTools(tmp_path / "profile")
    try:
        browser.call(
            "Emulation.setDeviceMetricsOverride",
            width=VIEWPORT_PX[0],
            height=VIEWPORT_PX[1],
            deviceScaleFactor=1,
            mobile=False,
        )
        browser.call("Page.navigate", url=viewer.urls[0])
        tempo_js = "(document.getElementById('qd-tempo') || {}).textContent"
        _wait_for(lambda: browser.evaluate(tempo_js) == "123.4 BPM", "the tempo on the page")
        text = browser.evaluate("document.body.innerText")
        assert "LOCKED" in text and "test-move" in text and "7.25 s" in text
        status_s = time.monotonic() - start_s

        def robot_shown(minimum: float) -> np.ndarray | None:
            shot = browser.screenshot()
            return shot if _robot_fraction(shot) > minimum else None

        with_robot = _wait_for(lambda: robot_shown(0.05), "the robot in the picture")
        robot_s = time.monotonic() - start_s
        # Live updates reach the page: the robot sinks under the floor, the dark pixels go.
        hidden = home.copy()
        hidden[2] = -10.0
        viewer.update(hidden)
        without_robot = _wait_for(
            lambda: None if robot_shown(0.01) is not None else browser.screenshot(),
            "the robot to leave the picture",
        )
        from PIL import Image

        Image.fromarray(with_robot.astype(np.uint8)).save(tmp_path / "with_robot.png")
        print(
            f"status {status_s:.1f} s, robot {robot_s:.1f} s ({_robot_fraction(with_robot):.1%}"
            f" dark, {_robot_fraction(without_robot):.1%} without), all"
            f" {time.monotonic() - start_s:.1f} s"
        )
    finally:
        browser.close()
        viewer.update(home)


def test_demo_entry_point_runs() -> None:
    from quaddance.live.viewer import main

    assert main(["--demo", "--port", "0", "--seconds", "1.0"]) == 0
