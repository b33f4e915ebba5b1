#!/usr/bin/python3
"""The cell dashboard in a real browser (headless Chromium through Selenium), as an operator
uses it: the stored plan is listed, its Run button starts it, the state goes busy then done,
the acceleration plot gets points; screenshots on the way.

Usage: dashboard.py URL PLAN_NAME SCREENSHOT_DIR [stop] [photo=PATH]
With `stop`, the run is stopped with the Stop button once busy, and the state must read idle
(the login case: URL is then the `/?token=...` URL serve printed). With `photo=PATH`, the
script plays the camera first: it posts the PNG to /api/verify while the page is open, and the
page must show the check (its event) with the photo and the found outlines drawn over it.
Run by host/cli/tests/integration/cli_serve_http.rs against `chladni serve --http` on the QEMU controller.
Prints one JSON line of what it saw; exits 1 naming the first thing that did not happen.
Needs Debian's chromium, chromium-driver and python3-selenium (scripts/install-deps.sh).
"""

import json
import os
import sys
import time
import urllib.request

try:
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.common.exceptions import StaleElementReferenceException, TimeoutException
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait
except ImportError as e:
    sys.exit(f"dashboard.py: {e}: install python3-selenium with scripts/install-deps.sh")

DRIVER = "/usr/bin/chromedriver"


def browser(extra=()):
    """Headless Chromium at a desktop size; root in a container needs --no-sandbox."""
    if not os.path.exists(DRIVER):
        sys.exit(f"dashboard.py: {DRIVER} missing: install chromium-driver with scripts/install-deps.sh")
    options = webdriver.ChromeOptions()
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                "--window-size=1280,920", "--hide-scrollbars", *extra):
        options.add_argument(arg)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(DRIVER), options=options)


def wait_for(driver, what, condition, timeout):
    """Waits until condition(driver) is true; exits naming `what` if it is not in time."""
    # The page rebuilds the plans table when it rereads the plans: a row may go stale.
    wait = WebDriverWait(driver, timeout, poll_frequency=0.05,
                         ignored_exceptions=(StaleElementReferenceException,))
    try:
        return wait.until(condition)
    except TimeoutException:
        state = driver.find_element(By.ID, "state").text
        message = driver.find_element(By.ID, "message").text
        driver.save_screenshot(os.path.join(SHOTS, "dashboard-failed.png"))
        sys.exit(f"dashboard.py: {what} did not happen within {timeout} s "
                 f"(state {state!r}, message {message!r}; screenshot dashboard-failed.png)")


def state_is(value):
    return lambda d: d.find_element(By.ID, "state").text.lower() == value


def points(driver):
    return int(driver.find_element(By.ID, "plot").get_attribute("data-points"))


def run_and_stop(driver, seen):
    """Stop once busy: the state must read idle, and the message name the stop's run."""
    driver.find_element(By.ID, "stop").click()
    stopped = time.monotonic()
    wait_for(driver, "the state idle after Stop", state_is("idle"), 10)
    seen["idle_after_stop_s"] = round(time.monotonic() - stopped, 2)
    seen["message"] = driver.find_element(By.ID, "message").text
    seen["errors"] = [e["message"] for e in driver.get_log("browser") if e["level"] == "SEVERE"]
    seen["points_busy"] = points(driver)


# Counts the outline colours of the shown photo (the server draws green as planned, red off).
COUNT_OUTLINES = """
const img = document.getElementById("verify-photo");
const c = document.createElement("canvas");
c.width = img.naturalWidth; c.height = img.naturalHeight;
const g = c.getContext("2d"); g.drawImage(img, 0, 0);
const d = g.getImageData(0, 0, c.width, c.height).data;
let green = 0, red = 0;
for (let i = 0; i < d.length; i += 4) {
  if (d[i] === 0 && d[i + 1] === 200 && d[i + 2] === 60) green++;
  if (d[i] === 230 && d[i + 1] === 30 && d[i + 2] === 30) red++;
}
return {width: c.width, height: c.height, green, red};
"""


def post_photo(driver, url, path, seen):
    """The camera's post, then what the open page shows of it (through its event stream)."""
    base = url.split("?")[0].rstrip("/")
    with open(path, "rb") as f:
        body = f.read()
    request = urllib.request.Request(base + "/api/verify", data=body, method="POST",
                                     headers={"Content-Type": "image/png"})
    with urllib.request.urlopen(request, timeout=30) as answer:
        posted = json.loads(answer.read())
    seq = str(posted["seq"])
    wait_for(driver, "the photo check on the page",
             lambda d: d.find_element(By.ID, "verify-result").get_attribute("data-seq") == seq, 10)
    wait_for(driver, "the checked photo loaded", lambda d: d.execute_script(
        "const i = document.getElementById('verify-photo'); return !i.hidden && i.complete && i.naturalWidth > 0;"), 10)
    seen["verify"] = {
        "posted": {k: posted[k] for k in ("seq", "result", "found", "oriented")},
        "result": driver.find_element(By.ID, "verify-result").text,
        "summary": driver.find_element(By.ID, "verify-summary").text,
        "parts_off": [li.text for li in driver.find_elements(By.CSS_SELECTOR, "#verify-parts li")],
        "outlines": driver.execute_script(COUNT_OUTLINES),
    }
    driver.find_element(By.ID, "verify-photo").screenshot(os.path.join(SHOTS, "dashboard-verify.png"))


def main(url, plan, shots, stop=False, photo=None):
    driver = browser()
    seen = {}
    try:
        driver.get(url)
        if photo:
            post_photo(driver, url, photo, seen)
        slot = wait_for(driver, f"the plan '{plan}' in the list", lambda d: next(
            (r.get_attribute("data-slot") for r in d.find_elements(By.CSS_SELECTOR, "#plans tr[data-slot]")
             if plan in r.text), False), 10)
        wait_for(driver, "the state idle (link up)", state_is("idle"), 10)
        row = driver.find_element(By.CSS_SELECTOR, f'#plans tr[data-slot="{slot}"]')
        seen["row"] = row.text
        row.find_element(By.CSS_SELECTOR, "button.run").click()
        started = time.monotonic()
        wait_for(driver, "the state busy after Run", state_is("busy"), 5)
        seen["busy_after_s"] = round(time.monotonic() - started, 2)
        seen["message"] = driver.find_element(By.ID, "message").text
        if stop:
            run_and_stop(driver, seen)
            return
        # Well into the run: the figure for the docs, with the plot drawn and the bar moving.
        wait_for(driver, "the second step", lambda d: d.find_element(By.ID, "step").text == "2 of 2", 15)
        time.sleep(1.5)
        seen["points_busy"] = points(driver)
        seen["progress"] = driver.find_element(By.ID, "progress-text").text
        driver.save_screenshot(os.path.join(shots, "dashboard.png"))
        wait_for(driver, "the state done at the plan's end", state_is("done"), 20)
        seen["done_after_s"] = round(time.monotonic() - started, 2)
        seen["points_done"] = points(driver)
        driver.save_screenshot(os.path.join(shots, "dashboard-done.png"))
        seen["errors"] = [e["message"] for e in driver.get_log("browser") if e["level"] == "SEVERE"]
    finally:
        driver.quit()
        print(json.dumps(seen), flush=True)
    if stop:
        if seen["errors"]:
            sys.exit(f"dashboard.py: the page logged errors: {seen['errors']}")
        return
    if seen["points_busy"] < 10:
        sys.exit(f"dashboard.py: the plot has {seen['points_busy']} points during the run, expected ≥ 10")
    if seen["errors"]:
        sys.exit(f"dashboard.py: the page logged errors: {seen['errors']}")


if __name__ == "__main__":
    extra = sys.argv[4:]
    photos = [a[len("photo="):] for a in extra if a.startswith("photo=")]
    if len(sys.argv) < 4 or any(a != "stop" and not a.startswith("photo=") for a in extra):
        sys.exit(__doc__)
    SHOTS = sys.argv[3]
    os.makedirs(SHOTS, exist_ok=True)
    main(sys.argv[1], sys.argv[2], SHOTS, stop="stop" in extra, photo=(photos or [None])[0])
