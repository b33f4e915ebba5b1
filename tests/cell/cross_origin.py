#!/usr/bin/python3
"""Attacks on the cell from the operator's own browser (headless Chromium): a page served from
another origin tries a no-CORS fetch, a plain HTML form POST (enctype text/plain, the body
shaped as JSON) and a JSON fetch at POST /api/run and /api/stop, and an image fetch (CORS and
no-CORS) at POST /api/verify; then a DNS-rebinding page
(evil.example mapped to 127.0.0.1 by the browser's resolver rules) reads and commands the
cell under its own name.

Usage: cross_origin.py CELL_URL
CELL_URL is the cell's base URL (http://127.0.0.1:PORT/). Prints one JSON line of what the
pages saw; the page sets its title to "attacked" when every attempt has been made, which
proves it ran. Whether anything ran on the controller is for the caller to check.
Run by host/cli/tests/integration/cli_serve_http.rs; needs chromium, chromium-driver, python3-selenium.
"""

import http.server
import json
import sys
import threading
import urllib.parse

from dashboard import browser, DRIVER  # noqa: F401 (one browser set-up for both scripts)

from selenium.webdriver.support.ui import WebDriverWait

PAGE = """<!doctype html><html><body>
<form id="f" method="POST" action="CELL/api/run" enctype="text/plain" target="sink">
<input name='{"slot":0,"x":"' value='"}'></form>
<iframe name="sink" id="sink"></iframe>
<script>
const cell = "CELL";
window.results = {};
async function attack() {
  try {
    await fetch(cell + "/api/run", {method: "POST", mode: "no-cors", body: '{"slot":0}',
                                    headers: {"Content-Type": "text/plain"}});
    results.nocors = "sent";
  } catch (e) { results.nocors = "error " + e.message; }
  try {
    await fetch(cell + "/api/stop", {method: "POST", mode: "no-cors", body: "{}"});
    results.nocors_stop = "sent";
  } catch (e) { results.nocors_stop = "error " + e.message; }
  try {
    const r = await fetch(cell + "/api/run", {method: "POST", body: '{"slot":0}',
                                              headers: {"Content-Type": "application/json"}});
    results.json = "status " + r.status;
  } catch (e) { results.json = "blocked: " + e.message; }
  // A photo from another site: a CORS fetch of an image body needs a preflight (never
  // granted); a no-CORS one goes out without its image type and is refused.
  const png = new Blob([new Uint8Array([137, 80, 78, 71, 13, 10, 26, 10])], {type: "image/png"});
  try {
    const r = await fetch(cell + "/api/verify", {method: "POST", body: png,
                                                 headers: {"Content-Type": "image/png"}});
    results.photo = "status " + r.status;
  } catch (e) { results.photo = "blocked: " + e.message; }
  try {
    await fetch(cell + "/api/verify", {method: "POST", mode: "no-cors", body: png});
    results.photo_nocors = "sent";
  } catch (e) { results.photo_nocors = "error " + e.message; }
  document.getElementById("sink").onload = () => {
    results.form = "submitted";
    document.title = "attacked";
  };
  document.getElementById("f").submit();
}
attack();
</script></body></html>"""


def serve_attack_page(cell):
    """The attacker's page on another port of loopback: another origin."""
    page = PAGE.replace("CELL", cell).encode()

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self):
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(page)))
            self.end_headers()
            self.wfile.write(page)

        def log_message(self, *args):
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


def main(cell):
    cell = cell.rstrip("/")
    port = urllib.parse.urlparse(cell).port
    server = serve_attack_page(cell)
    seen = {}
    driver = browser(["--host-resolver-rules=MAP evil.example 127.0.0.1"])
    try:
        driver.get(f"http://127.0.0.1:{server.server_address[1]}/")
        WebDriverWait(driver, 15, poll_frequency=0.05).until(lambda d: d.title == "attacked")
        seen["cross_origin"] = driver.execute_script("return window.results")
        # DNS rebinding: a page at evil.example:PORT is the cell's port under the attacker's
        # name; it reads and posts same-origin.
        driver.get(f"http://evil.example:{port}/api/status")
        seen["rebinding_page"] = driver.find_element("tag name", "body").text[:300]
        seen["rebinding_run"] = driver.execute_async_script("""
            const done = arguments[arguments.length - 1];
            fetch("/api/run", {method: "POST", body: '{"slot":0}',
                               headers: {"Content-Type": "application/json"}})
              .then(r => r.text().then(t => done(r.status + " " + t)))
              .catch(e => done("error " + e.message));""")
    finally:
        driver.quit()
        server.shutdown()
    print(json.dumps(seen), flush=True)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
