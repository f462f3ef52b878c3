#!/usr/bin/python3
"""Checks of what the quality engineer gets from a results folder (docs/results.md), run by the
virtual line test on its own results (`virtual_line.py --check-reports`) or alone:

    /usr/bin/python3 report_check.py BIN_DIR RESULTS_DIR WORK_DIR

- AQDEF: `hotgauge export aqdef` of the results, with one more part whose first feature was not
  measured, read back by the parser below (written here from the K-field notation, nothing
  shared with the C++ writer) and compared value for value with the JSON lines; the feature not
  measured must have no value (an empty K0001, attribute 255), never 0.
- Lot report: `hotgauge report lot` opened in a real headless Chromium: the number of charts
  (two per feature with a value), no image that failed to load, and every chart's pixels in a
  screenshot not blank (its data line or bars drawn).
- Part report: `hotgauge report part --results --sequence` of an archived part, in Chromium: two
  pictures per face and a tolerance band per feature, all loaded and not blank.
- The daemon's own: the drift state with every result, and its day's lot report in Chromium.
"""
import json
import os
import shutil
import subprocess
import sys

from PIL import Image


def result_lines(results_dir):
    """The result lines of a results folder, one per sequence (the last), in file order."""
    by_seq = {}
    for name in sorted(os.listdir(results_dir)):
        if name.endswith(".jsonl"):
            with open(os.path.join(results_dir, name)) as f:
                for text in f:
                    if text.strip():
                        line = json.loads(text)
                        by_seq[line["sequence"]] = line
    return list(by_seq.values())


def add_not_measured_part(results_dir):
    """Appends a copy of the last part with its first feature not measured; returns it."""
    lines = [l for l in result_lines(results_dir) if "verification" not in l]
    line = json.loads(json.dumps(lines[-1]))
    line["sequence"] = max(l["sequence"] for l in result_lines(results_dir)) + 1
    f = line["part"]["features"][0]
    f.update(hot_mm=None, cold_mm=None, deviation_mm=None, u_mm=None, u_cold_mm=None,
             verdict="NOT_MEASURED", reason="not measured: edge not found (report_check)")
    line["part"]["verdict"] = "NOT_MEASURED"
    day = sorted(n for n in os.listdir(results_dir) if n.endswith(".jsonl"))[-1]
    with open(os.path.join(results_dir, day), "a") as out:
        out.write(json.dumps(line) + "\n")
    return line


def parse_dfq(path):
    """AQDEF K-field notation: 'Kxxxx/i value' lines, CR LF. Characteristics by index i; values
    as blocks opened by K0001/i, the keys after it with the same i belonging to that value."""
    with open(path, "rb") as f:
        data = f.read()
    assert data.endswith(b"\r\n") and b"\n" not in data.replace(b"\r\n", b""), "lines not CR LF"
    chars, values, header = {}, [], {}
    for text in data.decode("ascii").split("\r\n")[:-1]:
        key, _, value = text.partition(" ")
        if "/" not in key:
            header[key] = value
            continue
        k, i = key.split("/")
        i = int(i)
        if k.startswith("K2") or k.startswith("K1"):
            chars.setdefault(i, {})[k] = value
        elif k == "K0001":
            values.append({"char": i, "K0001": value})
        else:
            assert values and values[-1]["char"] == i, f"{text}: not after its K0001/{i}"
            values[-1][k] = value
    return header, chars, values


def aqdef_time(iso):
    return f"{iso[8:10]}.{iso[5:7]}.{iso[0:4]}/{iso[11:19]}"


def check_aqdef(bin_dir, results_dir, work):
    copy = os.path.join(work, "aqdef-results")
    shutil.rmtree(copy, ignore_errors=True)
    shutil.copytree(results_dir, copy)
    missing = add_not_measured_part(copy)
    dfq = os.path.join(work, "results.dfq")
    subprocess.run([os.path.join(bin_dir, "src/app/hotgauge"), "export", "aqdef", copy,
                    "--out", dfq], check=True)
    header, chars, values = parse_dfq(dfq)
    parts = [l for l in result_lines(copy) if "verification" not in l]
    names = [f["name"] for f in parts[0]["part"]["features"]]
    assert int(header["K0100"]) == len(names) == len(chars), (header, len(chars))
    index = {chars[i]["K2001"]: i for i in chars}
    for f in parts[0]["part"]["features"]:
        c = chars[index[f["name"]]]
        assert abs(float(c["K2101"]) - f["nominal_mm"]) < 5e-5
        assert abs(float(c["K2110"]) - (f["nominal_mm"] + f["tolerance_mm"][0])) < 5e-5
        assert abs(float(c["K2111"]) - (f["nominal_mm"] + f["tolerance_mm"][1])) < 5e-5
        assert c["K2142"] == "mm"
    expected = [(l, f) for l in parts for f in l["part"]["features"]]
    assert len(values) == len(expected), (len(values), len(expected))
    read = {(v["K0009"].split(";")[0], v["char"]): v for v in values}
    for line, f in expected:
        v = read[(f"seq {line['sequence']}", index[f["name"]])]
        assert v["K0006"] == v["K0014"] == line["part"]["part_id"], v
        assert v["K0004"] == aqdef_time(line["time"]), v
        if f["reason"]:
            assert v["K0009"].startswith(f"seq {line['sequence']}; {f['verdict']}: "), v
        if f["cold_mm"] is None:
            assert v["K0001"] == "" and v["K0002"] == "255", (f["name"], v)
        else:
            assert abs(float(v["K0001"]) - f["cold_mm"]) <= 5e-7, (f["name"], v, f["cold_mm"])
            used = f["verdict"] in ("OK", "NOK")
            assert v["K0002"] == ("0" if used else "255"), (f["name"], v)
    gone = read[(f"seq {missing['sequence']}", index[names[0]])]
    assert gone["K0001"] == "" and "0" not in gone["K0001"], gone
    print(f"AQDEF: {len(values)} values of {len(parts)} parts read back as written, "
          f"'{names[0]}' of part {missing['sequence']} missing, not 0 ({dfq})")


# Injected into a copy of a page: what rendered, as JSON in a hidden element for --dump-dom.
PROBE = """<pre id='hg-probe' style='display:none'></pre><script>
const r = e => { const b = e.getBoundingClientRect();
  return [b.left + scrollX, b.top + scrollY, b.width, b.height]; };
document.getElementById('hg-probe').textContent = JSON.stringify({
  svg: [...document.querySelectorAll('svg')].map(e => [e.getAttribute('class'), r(e)]),
  img: [...document.querySelectorAll('img')].map(e => [e.complete && e.naturalWidth > 0, r(e)]),
  height: document.documentElement.scrollHeight});
</script>"""


def chromium(*args, budget_ms=3000):
    """Headless Chromium; a page that reloads itself needs a virtual time budget below its
    period (at a reload within the budget Chromium never returns)."""
    cmd = ["chromium", "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
           "--force-device-scale-factor=1", f"--virtual-time-budget={budget_ms}", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=True).stdout


def near(colour, ink, tolerance=40):
    return sum((a - b) ** 2 for a, b in zip(colour, ink)) <= tolerance ** 2


def check_page(html, ink=None, width=1280):
    """Loads the page in Chromium; returns what rendered and a screenshot of the whole page.
    Every svg and img must have a size and more than 3 colours; an svg whose class is in `ink`
    must have at least 20 pixels of that colour (its data drawn, not only frame and labels)."""
    ink = ink or {}
    html = os.path.abspath(html)
    probe = html + ".probe.html"
    with open(html) as f, open(probe, "w") as out:
        out.write(f.read().replace("</body>", PROBE + "</body>"))
    dom = chromium(f"--window-size={width},1000", "--dump-dom", "file://" + probe)
    marker = "<pre id=\"hg-probe\" style=\"display:none\">"
    start = dom.index(marker) + len(marker)
    seen = json.loads(dom[start:dom.index("</pre>", start)].replace("&quot;", '"'))
    png = html + ".png"
    chromium(f"--window-size={width},{seen['height']}", f"--screenshot={png}", "file://" + html)
    image = Image.open(png).convert("RGB")
    for kind, items in (("svg", seen["svg"]), ("img", seen["img"])):
        for what, (x, y, w, h) in items:
            assert w > 10 and h > 10, f"{html}: a {kind} ({what}) has no size"
            region = image.crop((int(x), int(y), int(x + w), int(y + h)))
            colours = region.getcolors(maxcolors=1 << 20)
            assert colours is None or len(colours) > 3, f"{html}: a {kind} ({what}) is blank"
            if kind == "svg" and what in ink:
                drawn = sum(n for n, c in colours or [] if near(c, ink[what]))
                assert drawn >= 20, f"{html}: {what} at {x:.0f},{y:.0f}: {drawn} data pixels"
    assert all(ok for ok, _ in seen["img"]), f"{html}: an image did not load"
    return seen, png


def check_lot_report(bin_dir, results_dir, work):
    html = os.path.join(work, "lot-report.html")
    subprocess.run([os.path.join(bin_dir, "src/app/hotgauge"), "report", "lot", results_dir,
                    "--out", html], check=True)
    with_values = set()
    for line in result_lines(results_dir):
        if "verification" not in line:
            for f in line["part"]["features"]:
                if f["cold_mm"] is not None and f["verdict"] in ("OK", "NOK"):
                    with_values.add(f["name"])
    seen, png = check_page(html, ink={"chart": (31, 95, 168), "histogram": (111, 159, 216)})
    classes = [c for c, _ in seen["svg"]]
    assert classes.count("chart") == classes.count("histogram") == len(with_values), classes
    print(f"lot report: {len(classes)} charts rendered in Chromium, none blank ({html}, {png})")


def check_part_report(bin_dir, results_dir, work):
    """`hotgauge report part` of the first production part the daemon archived, in Chromium:
    a range image and a deviation map per face, all loaded and not blank, a tolerance band per
    feature."""
    lines = [l for l in result_lines(results_dir) if "verification" not in l and l["archived_as"]]
    assert lines, f"{results_dir}: no archived production part"
    line = lines[0]
    out = os.path.join(work, "part-report")
    subprocess.run([os.path.join(bin_dir, "src/app/hotgauge"), "report", "part", "--results",
                    results_dir, "--sequence", str(line["sequence"]), "--out", out], check=True)
    html = os.path.join(out, f"part-{line['part']['part_id']}.html")
    seen, png = check_page(html)
    faces, features = len(line["part"]["faces"]), len(line["part"]["features"])
    classes = [c for c, _ in seen["svg"]]
    assert len(seen["img"]) == 2 * faces, (len(seen["img"]), faces)
    assert classes.count("band") == features, classes
    print(f"part report of sequence {line['sequence']}: {len(seen['img'])} pictures of {faces} "
          f"faces and {features} tolerance bands rendered in Chromium, none blank ({html}, {png})")


def check_daemon_report(results_dir):
    """The daemon's own files: the drift state with every production result (the line has too
    few parts for a baseline: BASELINE for every feature), and the day's lot report, which it
    rewrites after every part, rendering in Chromium."""
    for line in result_lines(results_dir):
        if "verification" in line:
            continue
        names = [f["name"] for f in line["part"]["features"]]
        assert sorted(line["drift"]) == sorted(names), line["drift"]
        assert set(line["drift"].values()) == {"BASELINE"}, line["drift"]
        assert line["die"] == 0, line["die"]
    pages = sorted(n for n in os.listdir(results_dir) if n.endswith(".report.html"))
    assert pages, f"{results_dir}: no day's lot report"

    def production_parts(page):  # a run across midnight has a second day with a part or two
        day = os.path.join(results_dir, page.replace(".report.html", ".jsonl"))
        if not os.path.exists(day):
            return 0
        with open(day) as f:
            return sum(1 for t in f if t.strip() and "verification" not in json.loads(t))

    page = max(pages, key=production_parts)
    seen, png = check_page(os.path.join(results_dir, page),
                           ink={"chart": (31, 95, 168), "histogram": (111, 159, 216)})
    assert [c for c, _ in seen["svg"]].count("chart") > 0, seen["svg"]
    print(f"daemon: drift state with every result; its lot report renders ({page}, {png})")


def main():
    bin_dir, results_dir, work = sys.argv[1:4]
    os.makedirs(work, exist_ok=True)
    check_aqdef(bin_dir, results_dir, work)
    check_lot_report(bin_dir, results_dir, work)
    check_part_report(bin_dir, results_dir, work)
    return 0


if __name__ == "__main__":
    sys.exit(main())
