"""Drives mocomp's operator console in a real headless Chromium (Debian's `chromium` and
`chromium-driver`) through Selenium, and prints one JSON object with what it saw.

usage: console_browser.py URL_WITH_TOKEN SCREENSHOT_DIR [loop|camera|calibrate|session|register|head|mri]

The console must serve a running `mocomp run` on the simulated world. With `loop` (the default)
the script checks, in the
page, that: without the token the page is read-only and a hold is refused (401); the token link
gives the page its cookie; the status changes as the loop runs; a tuning change takes and shows;
a bad value shows its error beside the field; the hold button holds the loop and resume resumes
it; the stop, after its confirmation, ends the run. It writes screenshots (tracking, holding) and
reports the loop-to-page latency the page measured. With `camera` (a session on the simulated
depth camera) it checks the IR frame with the pipeline's overlays shows, a scan area drawn with
the mouse and a new threshold take effect in the pipeline, a bad depth range shows its error
beside the field, and writes the IR screenshots (whole image, and the scan area drawn). With
`calibrate` (a `calibrate collect --dashboard`) it starts the collection from the page's button
after its confirmation and waits for the outcome. With `register` (a `register --dashboard`) it starts the registration from the page's
button and waits for the three landmarks and the outcome. With `mri` (a run whose `[head] mesh` is a
T1 phantom with a faint blob at the goal) it reads, in each of the three slices, where the blob is
and where the page drew the target and the coil, and changes the window. With `session` (a run with a `[session]` of
two targets, `hot` and `beside`, and the simulated stimulator) it checks the targets list shows,
"Go to target" takes the coil to `beside` by a path and back to tracking, the pulses show in the
events, and free-drive starts only from a hold and hands back. Any failure is an exception (exit 1).
Browser and driver paths: $MOCOMP_CHROMIUM (default /usr/bin/chromium) and
$MOCOMP_CHROMEDRIVER (default /usr/bin/chromedriver); nothing is downloaded.
"""

import json
import os
import statistics
import sys
import tempfile
import time

# Selenium must not try to fetch a browser or driver: use Debian's.
os.environ.setdefault("SE_OFFLINE", "true")

from selenium import webdriver  # noqa: E402
from selenium.webdriver.chrome.service import Service  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402


# How long a condition may take before the test calls the page hung. A deadline only catches a
# hung test: every wait returns as soon as its condition holds, and a starved machine (two test
# suites and stress-ng on two cores, the browser rendering without a GPU) once took more than
# 30 s to show an applied change. Waiting longer costs nothing when the page is right.
HUNG_S = 180.0
# The driver's log, one per helper process, removed when the helper succeeds.
DRIVER_LOG = os.path.join(tempfile.gettempdir(), f"mocomp-chromedriver-{os.getpid()}.log")


def wait(what, f, show=None):
    """Waits until `f()` is truthy and returns it; past HUNG_S, fails naming `what`, the last
    value (or exception) seen and, with `show`, what the page showed then."""
    deadline = time.monotonic() + HUNG_S
    last = None
    while time.monotonic() < deadline:
        try:
            last = f()
            if last:
                return last
        except Exception as e:  # a stale element while the page redraws
            last = e
        time.sleep(0.05)
    shown = ""
    if show is not None:
        try:
            shown = f"; the page showed {show()!r}"
        except Exception as e:  # the element itself gone
            shown = f"; the page showed nothing readable ({e})"
    raise AssertionError(f"timed out after {HUNG_S:.0f} s waiting for {what} (last: {last!r}){shown}")


def wait_text(d, what, element_id, holds):
    """Waits until the text of `element_id` satisfies `holds` and returns it; a timeout names the
    text the element had."""
    return wait(what, lambda: holds(text(d, element_id)) and text(d, element_id),
                show=lambda: text(d, element_id))


# What the page says when the loop latched a fault that only an operator re-arms and that a
# starved machine causes by itself: no robot state for 250 ms (two suites and stress-ng on two
# cores stop a process that long), and the controller's 50 ms watchdog then stopping the program.
STARVED = ("the robot's state is late", "robot: the control program is not running")
REARMS_PER_WAIT = 5


def starved(d):
    """The page says the loop latched a fault a starved machine causes by itself."""
    return text(d, "mode") == "faulted" and text(d, "reason") in STARVED


def wait_mode(d, what, mode):
    """Waits until the page's mode is `mode` (or one of a tuple of modes: modes the loop
    reaches by itself, no operator's hold meant, since a resume ends it), pressing Resume as an
    operator would when the page says the loop latched a fault of a starved machine (a second
    apart; said on stderr; past REARMS_PER_WAIT it is no starved machine, and fails)."""
    modes = mode if isinstance(mode, tuple) else (mode,)
    rearmed = []

    def reached():
        shown = text(d, "mode")
        if shown in modes:
            return shown
        if shown == "faulted" and text(d, "reason") in STARVED and (
                not rearmed or time.monotonic() - rearmed[-1] > 1.0):
            assert len(rearmed) < REARMS_PER_WAIT, f"re-armed {len(rearmed)} times waiting for {what}"
            print(f"waiting for {what}: the loop latched '{text(d, 'reason')}' (a starved "
                  "machine); resuming as an operator would", file=sys.stderr, flush=True)
            d.find_element(By.ID, "resume").click()
            rearmed.append(time.monotonic())
        return None

    return wait(what, reached, show=lambda: f"{text(d, 'mode')}: {text(d, 'reason')}")


def hand_guide(d):
    """Hold, then free-drive, until the page says the operator guides the arm. A fault a starved
    machine latched on the way (free-drive is refused while faulted, rightly) is re-armed as an
    operator would, and the hold and free-drive asked again (REARMS_PER_WAIT times at most)."""
    for _ in range(REARMS_PER_WAIT):
        wait_mode(d, "tracking before the hold", "tracking")
        d.find_element(By.ID, "hold").click()
        if wait("holding", lambda: starved(d) and "faulted" or (
                text(d, "mode") == "holding" and text(d, "reason") == "held by the operator")) == "faulted":
            continue
        wait("free-drive offered", lambda: starved(d) or not d.find_element(By.ID, "freedrive").get_attribute("disabled"))
        if starved(d):
            continue
        d.find_element(By.ID, "freedrive").click()
        guided = wait("hand-guided", lambda: starved(d) and "faulted" or (
            text(d, "reason") == "the operator guides the arm by hand" and "guided"))
        if guided == "guided":
            return
    raise AssertionError(f"no hand-guiding after {REARMS_PER_WAIT} faults of a starved machine")


def set_field(d, field_id, value, apply_id):
    """Types `value` into a form field and presses the form's Apply."""
    field = d.find_element(By.ID, field_id)
    field.clear()
    field.send_keys(value)
    d.find_element(By.ID, apply_id).click()


def settle(d, statuses=15):
    """Waits until the page has shown this many more statuses (for a screenshot that shows
    the loop running, not a fixed sleep). The page's own count: its list of latencies keeps
    only the newest 2,000, and a session a starved machine made long fills it."""
    n = d.execute_script("return window.mocomp.statuses")
    wait("more statuses", lambda: d.execute_script("return window.mocomp.statuses") >= n + statuses)


def number(s):
    """A tile's number, or None for its dash."""
    try:
        return float(s)
    except ValueError:
        return None


def text(d, element_id):
    # The DOM's text, not as styled (the mode badge is upper-cased by CSS).
    return d.find_element(By.ID, element_id).get_attribute("textContent").strip()


def browser():
    options = webdriver.ChromeOptions()
    options.binary_location = os.environ.get("MOCOMP_CHROMIUM", "/usr/bin/chromium")
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1400,1200", "--no-first-run", "--disable-extensions"):
        options.add_argument(arg)
    # Nothing of the browser's own beside the page: a non-root run on a starved machine once
    # took 103 s to type five keys and 165 s to click, while Chromium's on-device model service
    # failed to load its GPU backend in the same minutes; and a test browser has no
    # use for background downloads, component updates, sync or translation either.
    for arg in ("--disable-background-networking", "--disable-component-update",
                "--disable-default-apps", "--disable-sync",
                "--disable-features=OptimizationGuideOnDeviceModel,OptimizationGuideModelExecution,"
                "OptimizationHints,Translate,MediaRouter,AutofillServerCommunication"):
        options.add_argument(arg)
    # The driver's log of each command and the browser's answer, with times: shown when the
    # helper fails, so a command that hangs says where (the page, the driver or the machine).
    service = Service(executable_path=os.environ.get("MOCOMP_CHROMEDRIVER", "/usr/bin/chromedriver"),
                      log_output=DRIVER_LOG, service_args=["--log-level=INFO"])
    return webdriver.Chrome(options=options, service=service)


def driver_log_tail(lines=60, width=300):
    """The driver log's last lines, each cut to `width` characters (screenshots are long)."""
    try:
        with open(DRIVER_LOG, encoding="utf-8", errors="replace") as f:
            tail = f.readlines()[-lines:]
    except OSError as e:
        return f"(no driver log: {e})"
    return "".join(line if len(line) <= width else line[:width] + " …\n" for line in tail)


def loop_session(url, shots):
    base, token = url.split("/?token=")
    d = browser()
    seen = {"browser": d.capabilities.get("browserVersion")}
    try:
        # Without the token: read-only, and a hold from the page is refused.
        d.get(base + "/")
        wait("the read-only banner", lambda: d.find_element(By.ID, "auth").is_displayed())
        refused = d.execute_async_script(
            "const done = arguments[0];"
            "fetch('/api/hold', {method: 'POST'}).then(r => done(r.status));")
        assert refused == 401, refused
        seen["hold_without_token"] = refused
        # The link with the token: the cookie is set and the address bar loses the token.
        d.get(url)
        wait("the redirect to /", lambda: d.current_url.rstrip("/") == base)
        assert "token=" not in d.current_url
        wait("the banner to go", lambda: not d.find_element(By.ID, "auth").is_displayed())
        assert token not in d.page_source
        # The status changes as the loop runs.
        wait_mode(d, "tracking", "tracking")
        t0 = float(text(d, "t"))
        wait("the loop time to advance", lambda: float(text(d, "t")) > t0 + 0.5)
        dev = wait("a deviation", lambda: text(d, "deviation_mm") not in ("", "—") and text(d, "deviation_mm"))
        seen["deviation_mm_shown"] = float(dev)
        seen["rate_hz_shown"] = float(text(d, "rate_hz"))
        wait("the plot's history", lambda: d.execute_script("return window.mocomp.history.length") > 25)
        settle(d)
        d.execute_script("window.scrollTo(0, 0)")
        d.save_screenshot(os.path.join(shots, "console-tracking.png"))
        # A tuning change takes and shows.
        set_field(d, "param-speed_fraction", "0.45", "apply-params")
        wait_text(d, "the change applied", "params-result", lambda t: "applied: loop.speed_fraction" in t)
        wait("the form to show the new value",
             lambda: d.find_element(By.ID, "param-speed_fraction").get_attribute("value") == "0.45")
        cfg = d.execute_async_script(
            "const done = arguments[0];"
            "fetch('/api/config').then(r => r.json()).then(j => done(j.config.loop.speed_fraction));")
        assert abs(cfg - 0.45) < 1e-12, cfg
        seen["speed_fraction_after"] = cfg
        # A bad value shows its error beside the field, and changes nothing.
        before = d.find_element(By.ID, "param-max_tcp_speed_m_s").get_attribute("value")
        set_field(d, "param-max_tcp_speed_m_s", "-1", "apply-params")
        err = wait("the error beside the field", lambda: text(d, "error-max_tcp_speed_m_s"))
        assert "must be" in err, err
        assert "invalid" in d.find_element(By.ID, "param-max_tcp_speed_m_s").get_attribute("class")
        seen["bad_value_error"] = err
        still = d.execute_async_script(
            "const done = arguments[0];"
            "fetch('/api/config').then(r => r.json()).then(j => done(j.config.loop.max_tcp_speed_m_s));")
        assert str(still) == before or float(before) == still, (still, before)
        # Hold, then resume.
        d.find_element(By.ID, "hold").click()
        wait("holding", lambda: text(d, "mode") == "holding" and text(d, "reason") == "held by the operator")
        seen["held_reason"] = text(d, "reason")
        assert not d.find_element(By.ID, "resume").get_attribute("disabled")
        settle(d)
        d.execute_script("window.scrollTo(0, 0)")
        d.save_screenshot(os.path.join(shots, "console-holding.png"))
        # Teaching the goal while the head nods: refused, and the page says why.
        d.find_element(By.ID, "teach").click()
        wait("the teach confirmation", lambda: d.find_element(By.ID, "teach-dialog").is_displayed())
        d.find_element(By.ID, "confirm-teach").click()
        why = wait("the teach refusal", lambda: "moved" in text(d, "teach-result") and text(d, "teach-result"))
        seen["teach_refused"] = why
        d.find_element(By.ID, "resume").click()
        wait_mode(d, "tracking again", "tracking")
        rows = d.execute_script(
            "return [...document.querySelectorAll('#events tbody tr')].map(r => r.innerText)")
        assert any("hold: held by the operator" in r for r in rows), rows
        seen["events_shown"] = len(rows)
        lat = d.execute_script("return window.mocomp.latencies.slice()")
        lat = [x for x in lat if x == x]
        lat.sort()
        seen["latency_ms"] = {
            "n": len(lat),
            "median": statistics.median(lat),
            "p99": lat[min(len(lat) - 1, int(0.99 * (len(lat) - 1) + 0.5))],
        }
        # Stop, after its confirmation.
        d.find_element(By.ID, "stop").click()
        wait("the confirmation", lambda: d.find_element(By.ID, "stop-dialog").is_displayed())
        d.find_element(By.ID, "confirm-stop").click()
        wait_text(d, "stopped", "mode", lambda t: t == "stopped")
        seen["stopped"] = True
    finally:
        d.quit()
    return seen


def frame_brightness(d):
    """The mean of the IR canvas's red channel (0 before a frame is drawn)."""
    return d.execute_script(
        "const c = document.getElementById('ir-canvas');"
        "const px = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;"
        "let s = 0; for (let i = 0; i < px.length; i += 4) s += px[i];"
        "return s / (px.length / 4);")


def camera_config(d):
    return d.execute_async_script(
        "const done = arguments[0];"
        "fetch('/api/config').then(r => r.json()).then(j => done(j.config.tracker.camera.params));")


def camera_session(url, shots):
    from selenium.webdriver.common.action_chains import ActionChains
    d = browser()
    seen = {}
    try:
        d.get(url)
        wait_mode(d, "tracking on the camera's poses", "tracking")
        wait("the camera panel", lambda: d.find_element(By.ID, "camera-panel").is_displayed())
        wait("an IR frame drawn", lambda: frame_brightness(d) > 10)
        wait_text(d, "the marker found", "camera-meta", lambda t: "FRE" in t)
        seen["camera_meta"] = text(d, "camera-meta")
        settle(d)
        d.execute_script("document.getElementById('camera-panel').scrollIntoView()")
        d.save_screenshot(os.path.join(shots, "console-ir-whole.png"))
        # A new threshold takes effect in the pipeline.
        set_field(d, "cam-ir_threshold", "25000", "apply-camera")
        wait_text(d, "the threshold applied", "camera-result", lambda t: "applied: tracker.camera.params.ir_threshold" in t)
        assert camera_config(d)["ir_threshold"] == 25000
        # A scan area drawn with the mouse around the middle of the frame.
        canvas = d.find_element(By.ID, "ir-canvas")
        d.execute_script("arguments[0].scrollIntoView({block: 'center'})", canvas)
        wait("the frame in view", lambda: d.execute_script(
            "const r = arguments[0].getBoundingClientRect();"
            "return r.top >= 0 && r.bottom <= window.innerHeight;", canvas))
        w, h = canvas.size["width"], canvas.size["height"]
        ActionChains(d).move_to_element_with_offset(canvas, int(-0.2 * w), int(-0.2 * h)) \
            .click_and_hold().move_by_offset(int(0.2 * w), int(0.2 * h)) \
            .move_by_offset(int(0.2 * w), int(0.2 * h)).release().perform()
        area = wait("the scan area applied", lambda: camera_config(d)["scan_area"])
        assert 80 <= area[0] < 180 and 60 <= area[1] < 150 and 330 < area[2] <= 430 and 270 < area[3] <= 370, area
        seen["scan_area"] = area
        wait("the pipeline to use it",
             lambda: d.execute_script("return window.mocomp.status.camera.blobs") == 4)
        wait("the form to show it", lambda: d.find_element(By.ID, "cam-scan_area").get_attribute("value") != "")
        # A bad depth range shows its error beside the field, and changes nothing.
        set_field(d, "cam-depth_min_mm", "3000", "apply-camera")
        err = wait("the error beside the field", lambda: text(d, "cam-error-depth_min_mm"))
        assert "depth_max_mm" in err, err
        assert camera_config(d)["depth_min_mm"] == 400
        seen["bad_value_error"] = err
        # Tracking on, with the new scan area.
        wait_text(d, "found in the scan area", "camera-meta", lambda t: "FRE" in t)
        wait_mode(d, "tracking with the new scan area", ("tracking", "approaching"))
        settle(d)
        d.execute_script("document.getElementById('camera-panel').scrollIntoView()")
        d.save_screenshot(os.path.join(shots, "console-ir-scan-area.png"))
        seen["mode"] = text(d, "mode")
    finally:
        d.quit()
    return seen


def calibrate_session(url, shots):
    d = browser()
    seen = {}
    try:
        d.get(url)
        panel = lambda: d.find_element(By.ID, "calibration-panel")  # noqa: E731
        wait("the calibration panel", lambda: panel().is_displayed())
        start = lambda: d.find_element(By.ID, "start-calibration")  # noqa: E731
        wait("the start button", lambda: start().get_attribute("disabled") is None)
        # No loop runs: its buttons are off.
        assert d.find_element(By.ID, "hold").get_attribute("disabled") is not None
        seen["waiting"] = text(d, "reason")
        start().click()
        wait("the confirmation", lambda: d.find_element(By.ID, "calibrate-dialog").is_displayed())
        d.find_element(By.ID, "confirm-calibrate").click()
        # A collection that failed says why on the page at once: no reason to wait it out.
        def first_pose_or_failure():
            if "failed" in text(d, "mode"):
                return text(d, "cal-text") or "failed"
            return int(d.find_element(By.ID, "cal-progress").get_attribute("value")) >= 1

        if isinstance(got := wait("the first pose", first_pose_or_failure), str):
            raise AssertionError(f"the collection failed: {got!r}")
        seen["collecting"] = text(d, "mode")
        wait_text(d, "the outcome", "cal-text", lambda t: "saved" in t)
        rows = d.execute_script(
            "return [...document.querySelectorAll('#events tbody tr')].map(r => r.innerText)")
        assert any("measured" in r for r in rows), rows
        seen["events_shown"] = len(rows)
        seen["outcome"] = text(d, "cal-text")
        seen["mode"] = text(d, "mode")
        d.execute_script("window.scrollTo(0, 0)")
        d.save_screenshot(os.path.join(shots, "console-calibration.png"))
    finally:
        d.quit()
    return seen


def register_session(url, shots):
    d = browser()
    seen = {}
    try:
        d.get(url)
        panel = lambda: d.find_element(By.ID, "navigation-panel")  # noqa: E731
        wait("the navigation panel", lambda: panel().is_displayed())
        start = lambda: d.find_element(By.ID, "start-navigation")  # noqa: E731
        wait("the start button", lambda: start().get_attribute("disabled") is None)
        assert d.find_element(By.ID, "hold").get_attribute("disabled") is not None
        seen["waiting"] = text(d, "reason")
        start().click()
        wait("the landmarks", lambda: len(d.find_elements(By.CSS_SELECTOR, "#nav-landmarks tbody tr")) == 3)
        seen["landmarks"] = [r.text for r in d.find_elements(By.CSS_SELECTOR, "#nav-landmarks tbody tr")]
        wait_text(d, "the outcome", "nav-result", lambda t: "registered: FRE" in t)
        seen["result"] = [li.text for li in d.find_elements(By.CSS_SELECTOR, "#nav-result li")]
        rows = d.execute_script(
            "return [...document.querySelectorAll('#events tbody tr')].map(r => r.innerText)")
        seen["events"] = rows
        seen["mode"] = text(d, "mode")
        d.execute_script("document.getElementById('navigation-panel').scrollIntoView()")
        d.save_screenshot(os.path.join(shots, "console-registration.png"))
    finally:
        d.quit()
    return seen


def session_session(url, shots):
    d = browser()
    seen = {}
    try:
        d.get(url)
        wait_mode(d, "tracking on the start target", "tracking")
        options = wait("the targets", lambda: d.execute_script(
            "const s = document.getElementById('target-select');"
            "return s.options.length ? [...s.options].map(o => o.value) : null"))
        assert options == ["hot", "beside"], options
        seen["targets_shown"] = options
        # Free-drive is offered only from a hold.
        assert d.find_element(By.ID, "freedrive").get_attribute("disabled")
        d.execute_script("document.getElementById('target-select').value = 'beside'")
        d.find_element(By.ID, "go-target").click()
        wait_mode(d, "the path to it", "approaching")
        wait_mode(d, "tracking it", "tracking")
        # The dose tile, shown once the coil model gives a dose.
        wait("the dose tile", lambda: d.find_element(By.ID, "dose-tile").is_displayed())
        seen["dose_pct"] = wait("a dose", lambda: number(text(d, "dose_pct")))
        seen["dose_v_per_m"] = number(text(d, "dose_v_per_m"))
        rows = lambda: d.execute_script(
            "return [...document.querySelectorAll('#events tbody tr')].map(r => r.innerText)")
        wait("the selection in the events", lambda: any("target beside selected" in r for r in rows()))
        # A gated pulse on the new target. Not simply the first pulse on it: one the stimulator
        # fired through the old target's open gate can reach the robot's input just after the
        # switch, and is rightly logged on the new target as off target (a busy machine widens
        # that window).
        pulse = wait("a gated pulse in the events", lambda: next(
            (r for r in rows() if "pulse on beside" in r and "gate open" in r), None))
        seen["pulse_row"] = pulse
        # The tiles: the gate open, the pulses counted with the last one's error.
        wait_text(d, "the gate tile open", "gate", lambda t: t == "open")
        seen["pulses_tile"] = wait("pulses counted", lambda: int(text(d, "pulses") or 0))
        seen["pulse_last"] = text(d, "pulse-last")
        # The plot: tracking's tenths of a millimetre drawn well above the axis although the
        # paths' hundreds are in the same 30 s.
        seen["plot"] = d.execute_script("return window.mocomp.plot")
        hand_guide(d)
        seen["guided_reason"] = text(d, "reason")
        settle(d)
        d.execute_script("window.scrollTo(0, 0)")
        d.save_screenshot(os.path.join(shots, "console-session.png"))
        d.find_element(By.ID, "handback").click()
        wait_text(d, "held again after the hand-over", "reason", lambda t: t == "held by the operator")
        d.find_element(By.ID, "resume").click()
        wait_mode(d, "tracking after the hand-over", "tracking")
        seen["tracking_after_handback"] = True
        d.find_element(By.ID, "stop").click()
        wait("the confirmation", lambda: d.find_element(By.ID, "stop-dialog").is_displayed())
        d.find_element(By.ID, "confirm-stop").click()
        wait_text(d, "stopped", "mode", lambda t: t == "stopped")
    finally:
        d.quit()
    return seen


def head_session(url, shots):
    """The 3-D view on a scalp: the scene carries the decimated mesh, and the page draws it in
    the head model's colour around the head's place."""
    d = browser()
    seen = {}
    try:
        d.get(url)
        wait_mode(d, "tracking", "tracking")
        scene = d.execute_async_script(
            "const done = arguments[0];"
            "fetch('/api/scene').then(r => r.json()).then(j => done(j));")
        mesh = scene.get("head_mesh")
        assert mesh, scene.keys()
        seen["page_triangles"] = len(mesh["triangles"])
        seen["page_vertices"] = len(mesh["vertices_mm"])
        settle(d)
        # The head model's colour (#c7a98f) in the 3-D view, drawn with the scene as it is and
        # again without the mesh (in one synchronous script, so no status redraws between).
        counts = d.execute_script(
            "const c = document.getElementById('view3d'), g = c.getContext('2d');"
            "const count = () => { const px = g.getImageData(0, 0, c.width, c.height).data;"
            "  let n = 0; for (let i = 0; i < px.length; i += 4) {"
            "    if (Math.abs(px[i] - 199) < 25 && Math.abs(px[i + 1] - 169) < 25 &&"
            "        Math.abs(px[i + 2] - 143) < 25 && px[i + 3] > 0) n++; } return n; };"
            "const s = window.mocomp.scene; drawScene(); const with_mesh = count();"
            "const mesh = s.head_mesh; s.head_mesh = null; drawScene(); const without = count();"
            "s.head_mesh = mesh; drawScene(); return [with_mesh, without];")
        seen["head_pixels"], seen["head_pixels_without_mesh"] = counts
        d.execute_script("document.getElementById('view3d').scrollIntoView()")
        d.save_screenshot(os.path.join(shots, "console-scalp.png"))
    finally:
        d.quit()
    return seen


# In each slice the page shows: the bright blob's centroid (slice pixels: grey within `band`),
# how many pixels it has, where the page drew the target and the coil, and the scale it drew at.
MRI_BLOB = """
const m = window.mocomp.mri, band = arguments[0], out = {};
for (const plane of ['axial', 'coronal', 'sagittal']) {
  const b = m.bitmaps[plane];
  const c = document.createElement('canvas'); c.width = b.width; c.height = b.height;
  const g = c.getContext('2d'); g.drawImage(b, 0, 0);
  const px = g.getImageData(0, 0, b.width, b.height).data;
  let su = 0, sv = 0, n = 0;
  for (let v = 0; v < b.height; v++) for (let u = 0; u < b.width; u++) {
    const x = px[4 * (v * b.width + u)];
    if (x >= band[0] && x <= band[1]) { su += u; sv += v; n++; }
  }
  const d = m.drawn[plane];
  // The canvas as drawn: green (the target's cross) on its arm, 7 px right of the centre.
  const k = d.scale, cv = document.getElementById('mri-' + plane);
  const at = cv.getContext('2d').getImageData(Math.floor((d.target_px[0] + 0.5) * k) + 7,
    Math.floor((d.target_px[1] + 0.5) * k), 1, 1).data;
  out[plane] = { blob: n ? [su / n, sv / n] : null, blob_pixels: n, target_px: d.target_px,
    coil_px: d.coil_px, scale: k, size: [b.width, b.height], cross_rgb: [at[0], at[1], at[2]] };
}
return out;
"""


def mri_session(url, shots):
    d = browser()
    seen = {}
    try:
        d.get(url)
        wait_mode(d, "tracking", "tracking")
        wait("the MRI panel", lambda: d.find_element(By.ID, "mri-panel").is_displayed())
        wait("the three slices with the target and the coil", lambda: d.execute_script(
            "const m = window.mocomp.mri; return ['axial', 'coronal', 'sagittal'].every("
            "p => m.drawn[p] && m.drawn[p].target_px && m.drawn[p].coil_px)"))
        settle(d)
        seen["meta"] = d.execute_script(
            "const m = window.mocomp.mri.meta; return { step_mm: m.step_mm, window: m.window,"
            " landmarks: m.landmarks.length, eeg: m.eeg.length, bounds_mm: m.bounds_mm };")
        # The blob of 40 in a window of the volume's 1st to 99.5th percentile (0 to 150): grey 68.
        seen["planes"] = d.execute_script(MRI_BLOB, [55, 85])
        d.execute_script("document.getElementById('mri-panel').scrollIntoView()")
        d.save_screenshot(os.path.join(shots, "console-mri.png"))
        # A narrower window (0 to 40) makes the blob white.
        set_field(d, "mri-lo", "0", "mri-window")
        set_field(d, "mri-hi", "40", "mri-window")
        wait("the slices in the new window", lambda: d.execute_script(
            "return window.mocomp.mri.window[1] === 40 && !window.mocomp.mri.loading"))
        seen["planes_window_40"] = wait("the blob white", lambda: (
            lambda r: r if all(p["blob_pixels"] > 0 for p in r.values()) else None)(
            d.execute_script(MRI_BLOB, [250, 255])))
    finally:
        d.quit()
    return seen


if __name__ == "__main__":
    which = sys.argv[3] if len(sys.argv) > 3 else "loop"
    run = {"camera": camera_session, "calibrate": calibrate_session,
           "session": session_session, "head": head_session,
           "register": register_session, "mri": mri_session}.get(which, loop_session)
    try:
        print(json.dumps(run(sys.argv[1], sys.argv[2])))
        os.remove(DRIVER_LOG)
    except Exception:
        print(f"the driver's log ({DRIVER_LOG}), its last lines:\n{driver_log_tail()}", file=sys.stderr)
        raise
