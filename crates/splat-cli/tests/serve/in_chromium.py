"""`splat serve` in a real headless Chromium, driven over the Chrome DevTools protocol.

Usage: python3 in_chromium.py SPLAT CHROMIUM WORKDIR [SCREENSHOT.png]

Starts `splat serve` on the demo scene, checks that requests without the token, with a wrong
token or with an oversized body are refused, then opens the page in Chromium and:
  - waits for frames and reads the canvas back;
  - chooses the exact method from the panel's menu and compares the canvas with the PNG of
    `splat render --method exact` at the camera the server reports (within one 8-bit level,
    the viewer's own tolerance), then Algorithm 1 stopped at 16 frames with `splat render
    --method stochastic --spp 16`;
  - drags on the view and checks that the camera moved and the accumulation restarted, presses
    2 and checks the display shows depth, presses W and checks the camera flew, turns the wheel
    and checks it dollied; pauses (the frame count holds), resumes and restarts from the panel;
  - switches to the splatting pipeline and sets its samples per pixel from the panel;
  - checks that clients that never read their frame, or go away, hold up nothing;
  - opens a second page and checks that it shows the same accumulation;
  - takes a screenshot (the README's) when asked.
Exits non-zero with the reason on the first failure. Standard library only: the protocol runs
over --remote-debugging-pipe (JSON messages ended by NUL on file descriptors 3 and 4).
"""

import base64
import fcntl
import json
import os
import socket
import struct
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
import zlib


def fail(message):
    print(f"FAIL: {message}", file=sys.stderr)
    sys.exit(1)


def check(condition, message):
    if not condition:
        fail(message)


def wait_for(what, predicate, timeout=60.0, step=0.1):
    """Poll `predicate` until it returns a true value, failing after `timeout` seconds."""
    start = time.monotonic()
    while time.monotonic() - start < timeout:
        value = predicate()
        if value:
            return value
        time.sleep(step)
    fail(f"timed out after {timeout:.0f} s waiting for {what}")


class Browser:
    """Chromium over a DevTools pipe: commands by id, events skipped."""

    def __init__(self, chromium, profile):
        to_browser_r, self.to_browser = os.pipe()
        self.from_browser, from_browser_w = os.pipe()

        def pipes():
            # The browser reads commands on fd 3 and writes replies on fd 4: move both ends out
            # of the way first, as either may be 3 or 4 already.
            r = fcntl.fcntl(to_browser_r, fcntl.F_DUPFD, 10)
            w = fcntl.fcntl(from_browser_w, fcntl.F_DUPFD, 10)
            os.dup2(r, 3)
            os.dup2(w, 4)

        flags = [
            "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
            "--disable-background-networking", "--disable-component-update", "--disable-sync",
            "--remote-debugging-pipe", f"--user-data-dir={profile}", "--window-size=1100,700",
            "about:blank",
        ]
        self.process = subprocess.Popen(
            [chromium, *flags], preexec_fn=pipes, close_fds=False,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )
        os.close(to_browser_r)
        os.close(from_browser_w)
        self.buffer = b""
        self.next_id = 0

    def send(self, method, params=None, session=None, timeout=60.0):
        self.next_id += 1
        message = {"id": self.next_id, "method": method, "params": params or {}}
        if session:
            message["sessionId"] = session
        os.write(self.to_browser, json.dumps(message).encode() + b"\0")
        start = time.monotonic()
        while time.monotonic() - start < timeout:
            while b"\0" not in self.buffer:
                chunk = os.read(self.from_browser, 1 << 20)
                if not chunk:
                    fail(f"Chromium closed the pipe during {method}")
                self.buffer += chunk
            raw, self.buffer = self.buffer.split(b"\0", 1)
            reply = json.loads(raw)
            if reply.get("id") == self.next_id:
                if "error" in reply:
                    fail(f"{method}: {reply['error']}")
                return reply.get("result", {})
        fail(f"no reply to {method}")

    def page(self, url):
        target = self.send("Target.createTarget", {"url": url})["targetId"]
        session = self.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        return Page(self, session)

    def close(self):
        try:
            self.send("Browser.close", timeout=10)
        except SystemExit:
            pass
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()


class Page:
    def __init__(self, browser, session):
        self.browser, self.session = browser, session

    def send(self, method, params=None):
        return self.browser.send(method, params, self.session)

    def eval(self, expression):
        result = self.send("Runtime.evaluate", {"expression": expression, "returnByValue": True, "awaitPromise": True})
        if "exceptionDetails" in result:
            fail(f"{expression}: {result['exceptionDetails']}")
        return result["result"].get("value")

    def splat(self):
        return self.eval("window.splat ? JSON.parse(JSON.stringify(window.splat)) : null") or {}

    def canvas(self):
        """The canvas's RGBA bytes and size."""
        value = self.eval("""(() => {
            const c = document.getElementById('canvas');
            const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
            let s = ''; for (let i = 0; i < d.length; i += 8192) s += String.fromCharCode(...d.subarray(i, i + 8192));
            return { w: c.width, h: c.height, rgba: btoa(s) };
        })()""")
        return value["w"], value["h"], base64.b64decode(value["rgba"])

    def centre(self):
        r = self.eval("(() => { const r = document.getElementById('canvas').getBoundingClientRect(); "
                      "return [r.x + r.width / 2, r.y + r.height / 2]; })()")
        return r

    def drag(self, dx, dy):
        x, y = self.centre()
        mouse = lambda kind, px, py, buttons: self.send("Input.dispatchMouseEvent", {
            "type": kind, "x": px, "y": py, "button": "left", "buttons": buttons, "clickCount": 1})
        mouse("mousePressed", x, y, 1)
        for i in range(1, 6):
            mouse("mouseMoved", x + dx * i / 5, y + dy * i / 5, 1)
        mouse("mouseReleased", x + dx, y + dy, 0)

    def wheel(self, delta_y):
        x, y = self.centre()
        self.send("Input.dispatchMouseEvent", {"type": "mouseWheel", "x": x, "y": y, "deltaX": 0, "deltaY": delta_y})

    def key(self, key, code):
        for kind in ("keyDown", "keyUp"):
            self.send("Input.dispatchKeyEvent", {"type": kind, "key": key, "code": code, "text": key if kind == "keyDown" else ""})


def settled(page, method, frames):
    """Wait until the page shows the finished accumulation of `frames` frames of `method`."""
    return wait_for(f"{frames} frames of {method}", lambda: (
        (s := page.splat()).get("state") and s["state"]["settings"]["trace"] == method
        and s["state"]["status"]["idle"] and s["job"] == s["state"]["status"]["job"] and s["frames"] == frames and s))


def against_splat_render(page, splat, work, options, what):
    """Compare the canvas with the PNG `splat render` writes with `options` at the camera the
    server reports: within one 8-bit level, the window's tolerance."""
    time.sleep(0.3)
    width, height, shown = page.canvas()
    camera = page.splat()["state"]["camera"]
    check((camera["width"], camera["height"]) == (width, height), f"canvas {width}×{height}, camera {camera}")
    cameras = os.path.join(work, "serve-camera.json")
    with open(cameras, "w") as f:
        json.dump([camera], f)
    reference = os.path.join(work, "serve-reference.png")
    render = subprocess.run([splat, "render", "--camera", cameras, *options, "--backend", "cpu", "-o", reference],
                            capture_output=True, text=True)
    check(render.returncode == 0, f"splat render failed: {render.stderr}")
    w, h, expected = png_rgba(reference)
    check((w, h) == (width, height), f"splat render wrote {w}×{h}, the page shows {width}×{height}")
    worst = max(abs(a - b) for i, (a, b) in enumerate(zip(shown, expected)) if i % 4 != 3)
    lit = sum(1 for i in range(0, len(expected), 4) if expected[i] > 16)
    print(f"{what}: the canvas against splat render's PNG: largest difference {worst} levels ({width}×{height})")
    check(lit > width * height // 80, "the view is nearly black")
    check(worst <= 1, f"{what}: the page differs from splat render's PNG by up to {worst} levels")


def choose(menu, value):
    """The script that picks `value` in the panel's menu `menu`, as a click would."""
    return (f"(() => {{ const s = document.getElementById({json.dumps(menu)}); s.value = {json.dumps(value)}; "
            "s.dispatchEvent(new Event('change')); })()")


def png_rgba(path):
    """The 8-bit RGB or RGBA pixels of a non-interlaced PNG, as RGBA bytes (width, height, bytes)."""
    data = open(path, "rb").read()
    check(data[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG")
    at, idat, header = 8, b"", None
    while at < len(data):
        length, kind = struct.unpack(">I4s", data[at:at + 8])
        body = data[at + 8:at + 8 + length]
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        at += 12 + length
    width, height, depth, colour, _, _, interlace = header
    check(depth == 8 and colour in (2, 6) and interlace == 0, f"{path}: a PNG this reader does not read ({header})")
    channels = 3 if colour == 2 else 4
    raw, stride = zlib.decompress(idat), width * channels
    rows, previous = [], bytearray(stride)
    for y in range(height):
        kind, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - channels] if i >= channels else 0
            b, c = previous[i], previous[i - channels] if i >= channels else 0
            if kind == 1:
                line[i] = (line[i] + a) & 255
            elif kind == 2:
                line[i] = (line[i] + b) & 255
            elif kind == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif kind == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(bytes(line))
        previous = line
    pixels = b"".join(rows)
    if channels == 3:
        pixels = b"".join(pixels[i:i + 3] + b"\xff" for i in range(0, len(pixels), 3))
    return width, height, pixels


def http(url, body=None):
    """Status and body of a GET (or a POST of `body`)."""
    try:
        with urllib.request.urlopen(urllib.request.Request(url, data=body), timeout=30) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


def main():
    splat, chromium, work = sys.argv[1:4]
    screenshot = sys.argv[4] if len(sys.argv) > 4 else None
    server = subprocess.Popen(
        [splat, "serve", "--backend", "cpu", "--port", "0", "--width", "640", "--height", "400"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    browser = None
    try:
        line = server.stdout.readline()
        check(line.startswith("splat serve: http://127.0.0.1:"), f"no URL printed: {line!r} {server.stderr.read() if server.poll() is not None else ''}")
        url = line.split()[-1]
        base, token = url.split("/?token=")

        # The token guards every request; bodies are bounded.
        check(http(base + "/")[0] == 403, "the page is served without the token")
        check(http(base + "/state?token=" + "0" * len(token))[0] == 403, "a wrong token is accepted")
        status, _ = http(base + "/settings?token=" + token, b"{" + b" " * 20000 + b"}")
        check(status == 413, f"an oversized body was answered {status}")
        status, said = http(base + "/settings?token=" + token, b'{"trace": "no-such-method"}')
        check(status == 400 and b"no-such-method" in said, f"a bad setting was answered {status}: {said!r}")
        check(http(base + "/../../etc/passwd?token=" + token)[0] == 404, "a path outside the routes is served")

        browser = Browser(chromium, tempfile.mkdtemp(dir=work))
        page = browser.page(url)
        first = wait_for("the first frames", lambda: (s := page.splat()).get("drawn", 0) >= 3 and s)
        print(f"page: {first['drawn']} frames drawn, {first['frames']} accumulated")

        # The panel's menu chooses the exact method: the page shows splat render's PNG.
        page.eval(choose("method", "exact"))
        settled(page, "exact", 1)
        against_splat_render(page, splat, work, ["--method", "exact"], "exact")

        # Algorithm 1 stopped after 16 frames (the panel's frame limit): the converged image is
        # splat render's with 16 frames.
        page.eval("(() => { const f = document.getElementById('max_frames'); f.value = 16; "
                  "f.dispatchEvent(new Event('change')); })()")
        page.eval(choose("method", "stochastic"))
        converged = settled(page, "stochastic", 16)
        against_splat_render(page, splat, work, ["--method", "stochastic", "--spp", "16"], "16 frames of Algorithm 1")
        page.eval("(() => { const f = document.getElementById('max_frames'); f.value = 1024; "
                  "f.dispatchEvent(new Event('change')); })()")

        # A drag turns the camera and restarts the accumulation; keys change the display and fly.
        before = page.splat()["state"]
        page.drag(80, 0)
        moved = wait_for("the dragged camera", lambda: (
            (s := page.splat())["state"]["camera"]["rotation"] != before["camera"]["rotation"]
            and s["job"] > converged["job"] and s))
        check(moved["state"]["view"] is None, "the camera moved but the page still shows the loaded view")
        page.eval("document.getElementById('canvas').focus()")
        page.key("2", "Digit2")
        wait_for("the depth display", lambda: page.splat()["state"]["settings"]["display"] == "depth")
        position = page.splat()["state"]["camera"]["position"]
        page.key("w", "KeyW")
        wait_for("the camera to fly", lambda: page.splat()["state"]["camera"]["position"] != position)
        distance = page.splat()["state"]["camera"]["position"]
        page.wheel(-240)
        wait_for("the wheel to dolly", lambda: page.splat()["state"]["camera"]["position"] != distance)
        print("input: the drag turned the camera, 2 showed depth, W flew, the wheel dollied")

        # Pause holds the frame count; restart starts a new accumulation of the same view.
        page.eval("document.getElementById('paused').click()")
        paused = wait_for("the pause", lambda: (s := page.splat())["state"]["settings"]["paused"]
                          and s["state"]["status"]["idle"] and s)
        time.sleep(0.5)
        check(page.splat()["state"]["status"]["frames"] == paused["state"]["status"]["frames"], "frames came while paused")
        page.eval("document.getElementById('paused').click()")
        wait_for("the resumption", lambda: not (s := page.splat()["state"])["settings"]["paused"]
                 and s["status"]["frames"] > paused["state"]["status"]["frames"])
        job = page.splat()["state"]["status"]["job"]
        page.eval("document.getElementById('restart').click()")
        wait_for("the restart", lambda: page.splat()["state"]["status"]["job"] > job)
        print(f"pause held {paused['state']['status']['frames']} frames; restart began job {page.splat()['state']['status']['job']}")

        # The splatting pipeline shows its parameters: a choice set from its menu reaches the
        # render (StochasticSplats at four samples a pixel).
        page.eval(choose("pipeline", "raster"))
        wait_for("the splatting controls", lambda: page.eval("!!document.getElementById('samples_per_pixel')"))
        page.eval(choose("samples_per_pixel", "4"))
        wait_for("four samples a pixel", lambda: (s := page.splat()["state"])["settings"]["params"]["raster-samples"] == "4"
                 and s["settings"]["pipeline"] == "raster" and s["status"]["frames"] >= 2)
        page.eval(choose("pipeline", "ray tracing"))
        wait_for("the ray-tracing controls", lambda: page.eval("!!document.getElementById('method')"))
        print("splatting: the pipeline and its samples per pixel chosen from the panel")

        # Back to colour: the frames accumulate; a second page shows the same accumulation.
        page.key("1", "Digit1")
        wait_for("Algorithm 1 to accumulate", lambda: (s := page.splat())["state"]["settings"]["trace"] == "stochastic"
                 and s["frames"] >= 8 and s["job"] == s["state"]["status"]["job"])
        # Clients that ask for frames and never read them, or go away mid-request, hold up
        # nothing: the page's frames keep coming.
        stalled = []
        host, port = base.removeprefix("http://").rsplit(":", 1)
        for i in range(4):
            c = socket.create_connection((host, int(port)))
            c.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1024)
            c.sendall(f"GET /frame?after=0&token={token} HTTP/1.1\r\nHost: x\r\n\r\n".encode())
            if i % 2:
                c.close()
            else:
                stalled.append(c)
        drawn = page.splat()["drawn"]
        wait_for("frames past the stalled clients", lambda: page.splat()["drawn"] >= drawn + 5)
        for c in stalled:
            c.close()
        print("stalled and vanished clients: the page's frames kept coming")

        second = browser.page(url)
        both = wait_for("the second page's frames", lambda: (
            (s := second.splat()).get("drawn", 0) >= 2 and s["state"] and s))
        check(both["state"]["settings"]["trace"] == "stochastic", "the second page shows other settings")
        check(both["job"] == page.splat()["job"], "the two pages show different accumulations")
        print(f"two pages: both on job {both['job']}")

        if screenshot:
            wait_for("64 frames for the screenshot", lambda: page.splat()["frames"] >= 64)
            shot = page.send("Page.captureScreenshot", {"format": "png"})["data"]
            with open(screenshot, "wb") as f:
                f.write(base64.b64decode(shot))
            print(f"screenshot: {screenshot}")
        print("ok")
    finally:
        if browser:
            browser.close()
        server.kill()
        server.wait()


if __name__ == "__main__":
    main()
