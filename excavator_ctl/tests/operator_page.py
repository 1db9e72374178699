"""Drives the operator page in headless Chromium over the Chrome DevTools Protocol.

Usage: operator_page.py URL SCREENSHOT.png TIMEOUT_S [estop|finish]

Opens URL, waits until the page shows the session's state updating (session time advancing), the
terrain map and open valves. Then, with `estop` (the default), clicks E-STOP and waits until the page
shows the controller's e-stop (safety Faulted, fault "emergency stop"); with `finish`, waits until the
session ends and the page says so (it keeps its last state). It saves a screenshot and prints what it
saw as JSON on stdout. Exits non-zero
with the reason on stderr when a step does not happen in time. Needs `chromium` (Debian) and the
`websockets` package (PyPI).
"""

import base64
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.request

from websockets.sync.client import connect


def fail(why):
    print(f"operator_page: {why}", file=sys.stderr)
    sys.exit(1)


class Page:
    """One page target of the browser. Every reply is awaited up to the run's deadline, not a
    fixed time: on a loaded machine the page's main thread can hold an evaluation back for tens of
    seconds (once 30 s in CI with both cores busy)."""

    def __init__(self, ws_url, deadline):
        self.ws = connect(ws_url, max_size=64 * 1024 * 1024, open_timeout=20)
        self.next_id = 0
        self.deadline = deadline

    def call(self, method, **params):
        self.next_id += 1
        self.ws.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            try:
                msg = json.loads(self.ws.recv(timeout=max(1.0, self.deadline - time.monotonic())))
            except TimeoutError:
                fail(f"{method}: no reply from the browser by the deadline")
            if msg.get("id") == self.next_id:
                if "error" in msg:
                    fail(f"{method}: {msg['error']}")
                return msg.get("result", {})

    def eval(self, expr):
        r = self.call("Runtime.evaluate", expression=expr, returnByValue=True)
        if "exceptionDetails" in r:
            fail(f"evaluating {expr!r}: {r['exceptionDetails']}")
        return r["result"].get("value")

    def wait_for(self, expr, what, deadline):
        while time.monotonic() < deadline:
            v = self.eval(expr)
            if v:
                return v
            time.sleep(0.1)
        state = self.eval("JSON.stringify(window.operatorPage && window.operatorPage.state)")
        fail(f"timed out waiting for {what}; the page's state: {state}")


def main():
    url, screenshot, timeout_s = sys.argv[1], sys.argv[2], float(sys.argv[3])
    mode = sys.argv[4] if len(sys.argv) > 4 else "estop"
    deadline = time.monotonic() + timeout_s
    browser = shutil.which("chromium") or fail("chromium is not installed")
    profile = tempfile.mkdtemp(prefix="operator-page-")
    proc = subprocess.Popen(
        [browser, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
         "--disable-dev-shm-usage", "--remote-debugging-port=0", f"--user-data-dir={profile}",
         "--window-size=1200,1100", "about:blank"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        port_file = os.path.join(profile, "DevToolsActivePort")
        while not os.path.exists(port_file) or os.path.getsize(port_file) == 0:
            if time.monotonic() > deadline or proc.poll() is not None:
                fail("chromium did not open its DevTools port")
            time.sleep(0.1)
        port = open(port_file).read().split()[0]
        targets = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list"))
        target = next(t for t in targets if t["type"] == "page")
        page = Page(target["webSocketDebuggerUrl"], deadline)
        page.call("Page.enable")
        page.call("Runtime.enable")
        page.call("Page.navigate", url=url)
        page.wait_for("!!(window.operatorPage && window.operatorPage.state)", "the first state", deadline)
        if mode == "finish":
            # However late the browser came, the page shows the session's end and its last state.
            page.wait_for("window.operatorPage.finished", "the end of the session", deadline)
            page.wait_for("!!window.operatorPage.terrain", "the terrain map", deadline)
            # The server has gone with the session: the page still shows its last state.
            time.sleep(1.0)
            before = "null"
        else:
            t0 = page.eval("window.operatorPage.state.time_s")
            page.wait_for(f"window.operatorPage.state.time_s > {t0} + 1.0", "the session time to advance", deadline)
            page.wait_for("!!window.operatorPage.terrain", "the terrain map", deadline)
            page.wait_for("window.operatorPage.state.valves.some((v) => v.command_pct !== null && Math.abs(v.command_pct) > 1)",
                          "the machine to move", deadline)
            before = page.eval("JSON.stringify(window.operatorPage.state)")
            page.wait_for("!document.getElementById('estop').disabled", "the e-stop button to be enabled", deadline)
            page.eval("document.getElementById('estop').click()")
            page.wait_for(
                "window.operatorPage.state.safety === 'Faulted' && "
                "(window.operatorPage.state.fault || '').includes('emergency stop') && "
                "document.getElementById('command-result').textContent.startsWith('estop: done')",
                "the e-stop to reach the controller", deadline)
        # The page is drawn: keep what it shows.
        time.sleep(0.3)
        shot = page.call("Page.captureScreenshot", format="png")
        with open(screenshot, "wb") as f:
            f.write(base64.b64decode(shot["data"]))
        after = page.eval("JSON.stringify(window.operatorPage.state)")
        shown = page.eval("({safety: document.getElementById('safety').textContent, "
                          "fault: document.getElementById('fault').textContent, "
                          "digs: document.getElementById('current-dig').textContent, "
                          "valves: document.getElementById('valves').textContent, "
                          "stage: document.getElementById('stage').textContent, "
                          "result: document.getElementById('command-result').textContent, "
                          "over: document.getElementById('session-over').textContent, "
                          "connection: document.getElementById('connection').textContent, "
                          "digsDone: document.getElementById('digs-done').textContent, "
                          "lastDig: document.getElementById('last-dig').textContent, "
                          "updates: window.operatorPage.updates})")
        print(json.dumps({"before": json.loads(before), "after": json.loads(after), "shown": shown}))
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
        shutil.rmtree(profile, ignore_errors=True)


if __name__ == "__main__":
    main()
