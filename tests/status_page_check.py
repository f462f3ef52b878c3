#!/usr/bin/python3
"""The daemon's status page (docs/operations.md "Status page") checked while the virtual line
runs (`virtual_line.py --check-status-page`): after each part, between parts, the page as a real
headless Chromium renders it (--dump-dom) must show that part as the newest result, its sequence
above the one shown after the part before, and every result it shows with the part id, overall
verdict and per-feature verdicts of its line in the day's .jsonl; the device table of the five
devices must be there; each face's range image must be a PNG that decodes
with pixels of more than 3 colours; the links to the results files must serve those files; a
path out of the results folder (raw request line, no client-side cleaning) must get 403 and a
POST 405. At the end, a screenshot of the page (not blank).
"""
import io
import json
import os
import re
import socket
import subprocess
import time
import urllib.request
from html.parser import HTMLParser
from urllib.parse import urlsplit

from PIL import Image

import report_check

# Chromium's virtual time: below the page's 2 s reload (report_check.chromium).
BUDGET_MS = 1000


class Page(HTMLParser):
    """What the page shows: result rows with their features, the images, links, the device
    section."""

    def __init__(self):
        super().__init__()
        self.results, self.images, self.links, self.devices = [], [], [], []
        self.health = None
        self.in_health = False

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        cls = a.get("class", "")
        if tag == "tr" and cls == "result":
            self.results.append({"sequence": int(a["data-sequence"]), "part_id": a["data-part"],
                                 "verdict": a["data-verdict"], "features": {}})
        elif tag == "span" and cls.split()[:1] == ["feature"]:
            self.results[-1]["features"][a["data-name"]] = a["data-verdict"]
        elif tag == "tr" and cls == "device":
            self.devices.append(a)
        elif tag == "img":
            self.images.append(a)
        elif tag == "a" and "href" in a:
            self.links.append(a["href"])
        elif a.get("id") == "health":
            self.in_health, self.health = True, ""

    def handle_endtag(self, tag):
        self.in_health = self.in_health and tag != "p"

    def handle_data(self, data):
        if self.in_health:
            self.health += data


def raw_request(url, method, target, body=b""):
    """The status code of a request whose target is sent exactly as given."""
    u = urlsplit(url)
    with socket.create_connection((u.hostname, u.port), timeout=10) as s:
        s.sendall(f"{method} {target} HTTP/1.1\r\nHost: {u.netloc}\r\nConnection: close\r\n"
                  f"Content-Length: {len(body)}\r\n\r\n".encode() + body)
        reply = b""
        while chunk := s.recv(65536):
            reply += chunk
    return int(reply.split(b" ", 2)[1])


# Loopback only: no proxy from the environment.
OPENER = urllib.request.build_opener(urllib.request.ProxyHandler({}))


def get(url, timeout=10):
    with OPENER.open(url, timeout=timeout) as r:
        return r.status, r.headers.get("Content-Type"), r.read()


class StatusPageCheck:
    def __init__(self, url, results_dir, workdir):
        self.url, self.results_dir, self.workdir = url, results_dir, workdir
        self.last_sequence = None
        self.checks = 0

    def wait_for_sequence(self, sequence, timeout=20):
        """The page is updated after the registers: wait (bounded) until it has the part."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            status = json.loads(get(self.url + "status.json")[2])
            if status["results"] and status["results"][0]["sequence"] >= sequence:
                return status
            time.sleep(0.1)
        raise AssertionError(f"status page: sequence {sequence} not shown within {timeout} s")

    def render(self):
        """The page as headless Chromium renders it (no script on the page: the DOM is the
        server's HTML as a browser parsed it)."""
        dom = report_check.chromium("--no-proxy-server", "--window-size=1280,1000", "--dump-dom",
                                    self.url,
                                    budget_ms=BUDGET_MS)
        page = Page()
        page.feed(dom)
        return page

    def after_part(self):
        lines = {l["sequence"]: l for l in report_check.result_lines(self.results_dir)}
        newest = max(lines)
        status = self.wait_for_sequence(newest)
        page = self.render()
        assert page.results, "status page: no result shown"
        top = page.results[0]
        assert top["sequence"] == newest, f"status page shows {top['sequence']}, not {newest}"
        if self.last_sequence is not None:
            assert top["sequence"] > self.last_sequence, \
                f"status page did not advance: {top['sequence']} after {self.last_sequence}"
        self.last_sequence = top["sequence"]
        for shown in page.results:
            line = lines[shown["sequence"]]["part"]
            assert shown["part_id"] == line["part_id"], (shown, line["part_id"])
            assert shown["verdict"] == line["verdict"], (shown, line["verdict"])
            want = {f["name"]: f["verdict"] for f in line["features"]}
            assert shown["features"] == want, (shown["sequence"], shown["features"], want)
        self.check_devices(page, status)
        png_bytes = self.check_pictures(page, status)
        self.check_links(page)
        self.check_refusals()
        self.checks += 1
        print(f"status page: sequence {top['sequence']} part {top['part_id']} "
              f"{top['verdict']} shown with {len(top['features'])} features, "
              f"{len(page.images)} range images (drawn in {status['pictures']['ms']:.0f} ms, "
              f"{png_bytes} bytes of PNG); page {len(get(self.url)[2])} bytes",
              flush=True)

    def check_devices(self, page, status):
        """The daemon reports its devices' health every control loop: after a part, the table
        of the six (docs/plc-modbus.md "Device health")."""
        assert page.health is not None, "status page: no device section"
        assert status["health_updated"] is not None, f"device health not reported: {page.health}"
        assert len(page.devices) == len(status["devices"]) == 6, page.devices

    def check_pictures(self, page, status):
        faces = status["pictures"]["faces"]
        assert faces and len(page.images) == len(faces), (page.images, faces)
        total = 0
        for img, face in zip(page.images, faces):
            assert img["src"] == face["href"], (img, face)
            code, kind, body = get(self.url.rstrip("/") + img["src"])
            assert code == 200 and kind == "image/png", (img["src"], code, kind)
            image = Image.open(io.BytesIO(body)).convert("RGB")
            assert image.size == (int(img["width"]), int(img["height"])), (image.size, img)
            colours = image.getcolors(maxcolors=1 << 20)
            assert colours is None or len(colours) > 3, f"{img['src']}: blank"
            total += len(body)
        return total

    def check_links(self, page):
        served = [h for h in page.links if re.match(r"^/results/[^/]+\.(csv|jsonl)$", h)]
        assert any(h.endswith(".csv") for h in served) and \
            any(h.endswith(".jsonl") for h in served), page.links
        for href in served:
            code, kind, body = get(self.url.rstrip("/") + href)
            with open(os.path.join(self.results_dir, href.split("/")[-1]), "rb") as f:
                on_disk = f.read()
            assert code == 200 and body == on_disk, (href, code, len(body), len(on_disk))

    def check_refusals(self):
        for target in ("/results/../../etc/passwd", "/results/%2e%2e/%2e%2e/etc/passwd"):
            code = raw_request(self.url, "GET", target)
            assert code == 403, f"GET {target}: {code}, not 403"
        for method in ("POST", "PUT", "DELETE"):
            code = raw_request(self.url, method, "/", b"state=stop")
            assert code == 405, f"{method} /: {code}, not 405"

    def screenshot(self, png):
        report_check.chromium("--no-proxy-server", "--window-size=1280,1300",
                              f"--screenshot={png}", self.url,
                              budget_ms=BUDGET_MS)
        image = Image.open(png).convert("RGB")
        colours = image.getcolors(maxcolors=1 << 20)
        assert colours is None or len(colours) > 20, f"{png}: blank"
        print(f"status page: {self.checks} parts checked, screenshot {png}", flush=True)
