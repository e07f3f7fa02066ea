"""Drive headless Chromium over the DevTools protocol on a pipe (no driver, no network).

Why this and not playwright/selenium: Chromium's ``--remote-debugging-pipe`` speaks
the DevTools protocol over file descriptors 3 (commands in) and 4 (events out) as
NUL-terminated JSON. That needs only the standard library and Debian's
``chromium`` package: no chromedriver version to match, no browser download, no TCP
debugging port. Used by the browser test and the report benchmark.

Network isolation is enforced three ways: a dead proxy for every scheme
(``--proxy-server``), ``Network.emulateNetworkConditions(offline=True)``, and
``Fetch`` interception that fails every http(s)/ws(s) request and records its URL in
:attr:`PageReport.blocked_requests`.
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from grfguard.errors import GrfguardError

__all__ = ["find_chromium", "PageReport", "ChromiumSession", "load_report", "CHROMIUM_FLAGS"]

#: Flags of every headless launch (network-free, reproducible).
CHROMIUM_FLAGS: tuple[str, ...] = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--no-default-browser-check",
    "--disable-extensions",
    "--disable-dev-shm-usage",
    "--proxy-server=http://127.0.0.1:9",
    "--proxy-bypass-list=<-loopback>",
    "--remote-debugging-pipe",
)


def find_chromium() -> str | None:
    """Path of a Chromium binary, or None.

    ``GRFGUARD_CHROMIUM`` (environment) names the binary explicitly (None if it is not
    an executable file); otherwise ``/usr/bin/chromium`` first, then the ``PATH``.
    """
    forced = os.environ.get("GRFGUARD_CHROMIUM")
    if forced:
        return forced if os.path.isfile(forced) and os.access(forced, os.X_OK) else None
    for cand in ("/usr/bin/chromium", "chromium", "chromium-browser", "google-chrome"):
        if os.path.isabs(cand):
            if os.access(cand, os.X_OK):
                return cand
        elif (p := shutil.which(cand)) is not None:
            return p
    return None


@dataclass
class PageReport:
    """What happened while a page loaded.

    Attributes:
        load_s: Navigation start to the ``load`` event, wall clock in [s].
        ready_s: Navigation start to ``window.grfguardReport.ready``, in [s].
        console_errors: Console ``error`` messages, uncaught exceptions, log errors.
        blocked_requests: URLs of network requests the page tried (all failed).
        requests: Every request URL the page made (file:, data:, blob: included).
        state: The value of ``window.grfguardReport`` plus DOM checks and the page's own
            timings in [ms] since navigation start (``domContentLoadedMs``,
            ``loadEventMs``, ``readyAtMs``; see load_report).
        screenshot: Path of the full-page PNG screenshot, if one was taken.
    """

    load_s: float = float("nan")
    ready_s: float = float("nan")
    console_errors: list[str] = field(default_factory=list)
    blocked_requests: list[str] = field(default_factory=list)
    requests: list[str] = field(default_factory=list)
    state: dict[str, Any] = field(default_factory=dict)
    screenshot: Path | None = None


class ChromiumSession:
    """One headless Chromium process with one page, spoken to over the DevTools pipe."""

    def __init__(self, chromium: str | None = None, width: int = 1400, height: int = 900) -> None:
        exe = chromium or find_chromium()
        if exe is None:
            raise GrfguardError(
                "Chromium not found (looked for /usr/bin/chromium); install it with "
                "`apt-get install -y chromium`"
            )
        self._profile = tempfile.mkdtemp(prefix="grfguard-chromium-")
        r_cmd, w_cmd = os.pipe()  # we write commands -> browser fd 3
        r_evt, w_evt = os.pipe()  # browser fd 4 -> we read
        args = [exe, *CHROMIUM_FLAGS, f"--user-data-dir={self._profile}",
                f"--window-size={width},{height}", "about:blank"]

        def _child() -> None:  # runs in the child between fork and exec
            import fcntl

            # Move both out of the way of 3 and 4 first (close-on-exec copies), then
            # dup2 to 3 and 4 (inheritable). Everything else Python opened is
            # non-inheritable (PEP 446), so close_fds=False leaks nothing.
            a = fcntl.fcntl(r_cmd, fcntl.F_DUPFD_CLOEXEC, 10)
            b = fcntl.fcntl(w_evt, fcntl.F_DUPFD_CLOEXEC, 10)
            os.dup2(a, 3)
            os.dup2(b, 4)

        self._proc = subprocess.Popen(
            args,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            close_fds=False,  # pass_fds would make the child close 3 and 4 again
            preexec_fn=_child,  # noqa: PLW1509 - single-threaded use in tests/benchmarks
        )
        os.close(r_cmd)
        os.close(w_evt)
        self._w = os.fdopen(w_cmd, "wb", buffering=0)
        self._r = os.fdopen(r_evt, "rb", buffering=0)
        self._buf = b""
        self._next_id = 0
        self.events: list[dict[str, Any]] = []
        self.width, self.height = width, height
        self.session: str | None = None
        try:
            target = self.call("Target.createTarget", {"url": "about:blank"})["targetId"]
            self.session = self.call(
                "Target.attachToTarget", {"targetId": target, "flatten": True}
            )["sessionId"]
        except BaseException:
            self.close()  # never leave our browser process behind
            raise

    # -- protocol --------------------------------------------------------------------
    def _read_message(self, timeout_s: float) -> dict[str, Any]:
        import select

        deadline = time.monotonic() + timeout_s
        while b"\0" not in self._buf:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError("no message from Chromium within the timeout")
            ready, _, _ = select.select([self._r], [], [], left)
            if ready:
                chunk = os.read(self._r.fileno(), 1 << 20)
                if not chunk:
                    raise GrfguardError("Chromium closed the DevTools pipe (crashed?)")
                self._buf += chunk
        msg, self._buf = self._buf.split(b"\0", 1)
        return json.loads(msg)

    def send(self, method: str, params: dict[str, Any] | None = None,
             session: bool = True) -> int:
        """Send one command; return its id."""
        self._next_id += 1
        msg: dict[str, Any] = {"id": self._next_id, "method": method, "params": params or {}}
        if session and self.session:
            msg["sessionId"] = self.session
        self._w.write(json.dumps(msg).encode() + b"\0")
        return self._next_id

    def call(self, method: str, params: dict[str, Any] | None = None,
             timeout_s: float = 60.0) -> dict[str, Any]:
        """Send one command and wait for its result (events meanwhile go to ``events``)."""
        mid = self.send(method, params)
        deadline = time.monotonic() + timeout_s
        while True:
            msg = self._read_message(max(deadline - time.monotonic(), 0.001))
            if msg.get("id") == mid:
                if "error" in msg:
                    raise GrfguardError(f"DevTools {method} failed: {msg['error']}")
                return msg.get("result", {})
            self._on_event(msg)

    def pump(self, timeout_s: float) -> None:
        """Read events for up to ``timeout_s`` [s]."""
        deadline = time.monotonic() + timeout_s
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return
            try:
                self._on_event(self._read_message(left))
            except TimeoutError:
                return

    def _on_event(self, msg: dict[str, Any]) -> None:
        if msg.get("method") == "Fetch.requestPaused":
            p = msg["params"]
            self.events.append(msg)
            self.send("Fetch.failRequest", {"requestId": p["requestId"],
                                            "errorReason": "InternetDisconnected"})
            return
        if "method" in msg:
            self.events.append(msg)

    def evaluate(self, expression: str, timeout_s: float = 60.0) -> Any:
        """Evaluate a JavaScript expression in the page; return its JSON value."""
        r = self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True,
                                           "awaitPromise": True}, timeout_s=timeout_s)
        if "exceptionDetails" in r:
            raise GrfguardError(f"page script failed: {r['exceptionDetails']}")
        return r["result"].get("value")

    def close(self) -> None:
        """Close the browser and remove its profile directory."""
        try:
            self.send("Browser.close", session=False)
            self._proc.wait(timeout=10)
        except Exception:  # noqa: BLE001 - best effort, then kill our own process
            self._proc.kill()
            self._proc.wait(timeout=10)
        finally:
            for f in (self._w, self._r):
                try:
                    f.close()
                except OSError:
                    pass
            shutil.rmtree(self._profile, ignore_errors=True)

    def __enter__(self) -> ChromiumSession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


_STATE_JS = """
(() => {
  const s = window.grfguardReport || {};
  const figs = Array.from(document.querySelectorAll('div.fig')).map(d => {
    const paths = Array.from(d.querySelectorAll('.scatterlayer .trace path.js-line, '
                                               + '.scatterlayer .trace path.js-fill'));
    const r = d.getBoundingClientRect();
    return {
      id: d.id, sensor: d.dataset.sensor, expected: Number(d.dataset.traces),
      data_traces: (d.data || []).length,
      svg_traces: d.querySelectorAll('.scatterlayer .trace').length,
      drawn_paths: paths.filter(p => (p.getAttribute('d') || '').length > 20).length,
      path_chars: paths.reduce((a, p) => a + (p.getAttribute('d') || '').length, 0),
      shapes: d.querySelectorAll('.shapelayer path').length,
      width: r.width, height: r.height, top: r.top + window.scrollY,
    };
  });
  const nav = performance.getEntriesByType('navigation')[0] || {};
  return {ready: !!s.ready, errors: s.errors || [], renderMs: s.renderMs ?? null,
          readyAtMs: s.readyAtMs ?? null, firstFigureAtMs: s.firstFigureAtMs ?? null,
          domContentLoadedMs: nav.domContentLoadedEventEnd ?? null,
          loadEventMs: nav.loadEventEnd ?? null,
          figures: figs, summaryRows: document.querySelectorAll('#summary tbody tr').length,
          scriptSrcs: Array.from(document.querySelectorAll('script[src]')).map(e => e.src),
          pageHeight: document.documentElement.scrollHeight};
})()
"""


def load_report(
    html_path: str | Path,
    screenshot: str | Path | None = None,
    timeout_s: float = 60.0,
    chromium: str | None = None,
) -> PageReport:
    """Open an HTML report in headless Chromium with no network; report what happened.

    Args:
        html_path: The report file.
        screenshot: Optional PNG path for a full-page screenshot.
        timeout_s: Give up waiting for ``window.grfguardReport.ready`` after this [s].
        chromium: Chromium binary (default :func:`find_chromium`).

    Returns:
        Load and ready times, console errors, attempted network requests, DOM state.

    Raises:
        GrfguardError: If Chromium is missing or crashes.
        TimeoutError: If the page does not become ready within ``timeout_s``.
    """
    url = Path(html_path).resolve().as_uri()
    rep = PageReport()
    with ChromiumSession(chromium) as cr:
        cr.call("Page.enable")
        cr.call("Runtime.enable")
        cr.call("Log.enable")
        cr.call("Network.enable")
        cr.call("Network.emulateNetworkConditions", {"offline": True, "latency": 0,
                                                     "downloadThroughput": 0,
                                                     "uploadThroughput": 0})
        cr.call("Fetch.enable", {"patterns": [{"urlPattern": "http*"}, {"urlPattern": "ws*"}]})
        t0 = time.monotonic()
        cr.call("Page.navigate", {"url": url})
        loaded = False
        deadline = t0 + timeout_s
        while time.monotonic() < deadline:
            cr.pump(0.02)
            if not loaded and any(e.get("method") == "Page.loadEventFired" for e in cr.events):
                loaded = True
                rep.load_s = time.monotonic() - t0
            if loaded and cr.evaluate("!!(window.grfguardReport && window.grfguardReport.ready)"):
                rep.ready_s = time.monotonic() - t0
                break
        else:
            raise TimeoutError(f"{html_path} did not become ready within {timeout_s} s")
        rep.state = cr.evaluate(_STATE_JS)
        cr.pump(0.2)
        if screenshot is not None:
            h = int(min(rep.state.get("pageHeight", cr.height), 16000))
            cr.call("Emulation.setDeviceMetricsOverride",
                    {"width": cr.width, "height": h, "deviceScaleFactor": 1, "mobile": False})
            cr.pump(0.5)  # plotly is responsive: let it redraw at the new size
            shot = cr.call("Page.captureScreenshot", {"format": "png",
                                                      "captureBeyondViewport": True})
            out = Path(screenshot)
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_bytes(base64.b64decode(shot["data"]))
            rep.screenshot = out
        for e in cr.events:
            m, p = e.get("method"), e.get("params", {})
            if m == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
                rep.console_errors.append(
                    " ".join(str(a.get("value", a.get("description", ""))) for a in p["args"])
                )
            elif m == "Runtime.exceptionThrown":
                d = p.get("exceptionDetails", {})
                rep.console_errors.append(str(d.get("exception", {}).get("description", d)))
            elif m == "Log.entryAdded" and p.get("entry", {}).get("level") == "error":
                rep.console_errors.append(p["entry"].get("text", ""))
            elif m == "Network.requestWillBeSent":
                rep.requests.append(p["request"]["url"])
            elif m == "Fetch.requestPaused":
                rep.blocked_requests.append(p["request"]["url"])
    return rep
