"""`hotgauge remeasure` on the virtual line's archive (docs/results.md "Re-measuring the archive"),
called by virtual_line.py --check-remeasure after the line has stopped:

1. With the recipe the daemon used, every part's result equals the daemon's: the `part` of each
   new results line is the daemon's, wall times (stage_ms) aside, and the comparison finds every
   part unchanged. Not on a terminal: plain progress lines, no carriage returns.
2. With one tolerance tightened so that the new limit falls between the parts' values, the flips
   reported are exactly the parts whose value lies between the old and the new limit, and nothing
   else, in comparison.json and in the page as headless Chromium renders it. This run is on a
   pseudo-terminal: what a terminal shows has the progress bar redrawn in place, counting up to
   every part, with parts/s and the time left.
3. Ctrl-C (SIGINT) after the first part: exit 130, the parts written are the first ones, the ones
   the comparison and the page cover, each equal to the daemon's, and the page says it was
   stopped.
4. Bad input: a part whose recording is gone is listed with why and the others are measured; a
   recipe of another part is refused naming both; --out on the results read is refused.
"""
import glob
import json
import os
import pty
import re
import select
import signal
import subprocess
import time

import yaml

import report_check

REPO = os.path.abspath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
RECIPE = os.path.join(REPO, "config", "parts", "hub-a.yaml")


def result_lines(results_dir):
    """The results lines of a folder by sequence (report_check.result_lines: the last of each)."""
    return {j["sequence"]: j for j in report_check.result_lines(results_dir)}


def without_wall_times(value):
    """`value` without its wall times (every "stage_ms", the part's and the matcher's)."""
    if isinstance(value, dict):
        return {k: without_wall_times(v) for k, v in value.items() if k != "stage_ms"}
    if isinstance(value, list):
        return [without_wall_times(v) for v in value]
    return value


def check_same_as_daemon(daemon, out_dir, sequences=None):
    new = result_lines(os.path.join(out_dir, "results"))
    assert new, f"{out_dir}: no results written"
    want = set(sequences) if sequences is not None else {s for s, j in daemon.items()
                                                         if "verification" not in j}
    assert set(new) == want, f"sequences {sorted(new)}, expected {sorted(want)}"
    for seq, line in new.items():
        a, b = without_wall_times(daemon[seq]["part"]), without_wall_times(line["part"])
        if a != b:
            differ = [k for k in set(a) | set(b) if a.get(k) != b.get(k)]
            raise AssertionError(f"sequence {seq}: remeasured part differs from the daemon's "
                                 f"in {sorted(differ)}")
        assert line["time_ns"] == daemon[seq]["time_ns"], f"sequence {seq}: time"
    return new


def remeasure(bin_dir, results_dir, out_dir, recipe):
    return subprocess.run([os.path.join(bin_dir, "src", "app", "hotgauge"), "remeasure",
                           results_dir, "--out", out_dir, "--recipe", recipe],
                          capture_output=True, text=True, timeout=600)


def run_on_terminal(argv, interrupt_after=None, timeout=600):
    """argv on a pseudo-terminal (stdout and stderr): what it printed, its exit status. With
    `interrupt_after` (a regex), SIGINT as soon as the output matches it."""
    pid, fd = pty.fork()
    if pid == 0:
        os.execv(argv[0], argv)
    out, sent, t0 = b"", False, time.monotonic()
    while time.monotonic() - t0 < timeout:
        r, _, _ = select.select([fd], [], [], 1.0)
        if r:
            try:
                chunk = os.read(fd, 4096)
            except OSError:  # EIO: the child closed the terminal
                break
            if not chunk:
                break
            out += chunk
        if interrupt_after and not sent and re.search(interrupt_after, out.decode(errors="replace")):
            os.kill(pid, signal.SIGINT)
            sent = True
    _, status = os.waitpid(pid, 0)
    return out.decode(errors="replace"), os.waitstatus_to_exitcode(status)


def tightened_limit(values):
    """A feature and a limit between its parts' values: (name, side, limit, parts beyond it).
    Recipes keep lower <= 0 <= upper, so the upper limit comes down to a midpoint >= 0 or the
    lower one up to a midpoint <= 0."""
    for name, devs in sorted(values.items(), key=lambda kv: -len(kv[1])):
        devs = sorted(devs)
        mids = [(devs[j][0] + devs[j + 1][0]) / 2 for j in range(len(devs) - 1)]
        for m in mids:
            if m >= 0:
                return name, 1, m, sorted(seq for dev, seq in devs if dev > m)
        for m in reversed(mids):
            if m <= 0:
                return name, 0, m, sorted(seq for dev, seq in devs if dev < m)
    raise AssertionError(f"no feature has two OK values to put a limit between: {values}")


def tightened_recipe(daemon, workdir):
    """hub-a with one feature's limit between the parts' values: the recipe, the feature, the
    limit, the parts (sequences) whose value lies between the old and the new limit."""
    values = {}
    for seq, j in daemon.items():
        if "verification" in j:
            continue
        for f in j["part"]["features"]:
            if f["verdict"] == "OK" and f["cold_mm"] is not None:
                values.setdefault(f["name"], []).append((f["cold_mm"] - f["nominal_mm"], seq))
    name, side, limit, expected = tightened_limit(values)
    with open(RECIPE) as f:
        recipe = yaml.safe_load(f)
    for feat in recipe["features"]:
        if feat["name"] == name:
            feat["tolerance_mm"][side] = limit
    path = os.path.join(workdir, "hub-a-tightened.yaml")
    with open(path, "w") as f:
        yaml.safe_dump(recipe, f, sort_keys=False)
    return path, name, limit, expected


def page_rows(html, table):
    """The rows of the page's table `table` as headless Chromium rendered them (report_check.py):
    the page parses, and says what the comparison says."""
    import html as html_text
    dom = report_check.chromium("--dump-dom", "file://" + os.path.abspath(html))
    body = re.search(rf"<table class=\"{table}\">(.*?)</table>", dom, re.S)
    assert body, f"{html}: no table '{table}' rendered"
    rows = re.findall(r"<tr[^>]*>(.*?)</tr>", body.group(1), re.S)[1:]  # the header left out
    return [[html_text.unescape(re.sub(r"<[^>]+>", "", c)).strip()
             for c in re.findall(r"<td[^>]*>(.*?)</td>", r, re.S)] for r in rows]


def check_progress_on_terminal(screen, n):
    states = re.findall(r"\[[#.]+\] (\d+)/(\d+) parts +([\d.]+) parts/s +([\d:]+ (?:left|in all)|"
                        r"time left not known yet)", screen)
    assert states, f"no progress bar on the terminal:\n{screen}"
    counts = [int(d) for d, total, _, _ in states]
    assert all(int(total) == n for _, total, _, _ in states), states
    assert counts == sorted(counts) and counts[-1] == n, f"progress counts {counts}"
    assert "\r" in screen and "\x1b[K" in screen, "the bar is not redrawn in place"
    assert states[-1][3].endswith("in all"), states[-1]
    return counts


def check_remeasure(bin_dir, results_dir, workdir):
    daemon = result_lines(results_dir)
    parts = [s for s, j in daemon.items() if "verification" not in j]
    hotgauge = os.path.join(bin_dir, "src", "app", "hotgauge")

    same = os.path.join(workdir, "remeasure-same")
    r = remeasure(bin_dir, results_dir, same, RECIPE)
    assert r.returncode == 0, f"remeasure exit {r.returncode}: {r.stderr}"
    assert "\r" not in r.stderr and re.search(r"\d+/\d+ parts", r.stderr), r.stderr
    check_same_as_daemon(daemon, same)
    c = json.load(open(os.path.join(same, "comparison.json")))
    assert c["parts"] == len(parts) and c["unchanged"] == len(parts), c
    assert not c["flips"] and not c["part_flips"], c["flips"]
    print(f"remeasure with the daemon's recipe: {len(parts)} parts, every one equal to the "
          f"daemon's result (wall times aside)")

    recipe, name, limit, expected = tightened_recipe(daemon, workdir)
    tight = os.path.join(workdir, "remeasure-tightened")
    screen, rc = run_on_terminal([hotgauge, "remeasure", results_dir, "--out", tight, "--recipe",
                                  recipe])
    assert rc == 0, f"remeasure exit {rc}:\n{screen}"
    counts = check_progress_on_terminal(screen, len(parts))
    c = json.load(open(os.path.join(tight, "comparison.json")))
    flips = sorted((f["sequence"], f["feature"], f["before"], f["after"]) for f in c["flips"])
    assert flips == [(s, name, "OK", "NOK") for s in expected], \
        f"flips {flips}, expected {name} OK -> NOK on {expected}"
    rows = page_rows(os.path.join(tight, "remeasure.html"), "flips")
    assert sorted(int(r[0]) for r in rows) == expected and all(name in r for r in rows), rows
    # A limit moves verdicts, never values: every shift 0, every other part unchanged.
    assert all(f["n"] == 0 or f["worst_mm"] == 0 for f in c["shifts"]), c["shifts"]
    assert c["unchanged"] == len(parts) - len(expected), c["unchanged"]
    print(f"remeasure with a limit of {name} tightened to {limit:+.4f} mm: flips "
          f"{[s for s, *_ in flips]} exactly the parts between the limits; progress on a "
          f"terminal counted {counts}")

    stopped = os.path.join(workdir, "remeasure-stopped")
    screen, rc = run_on_terminal([hotgauge, "remeasure", results_dir, "--out", stopped, "--recipe",
                                  RECIPE, "--jobs", "1"], interrupt_after=r"\] 1/\d+ parts")
    assert rc == 130, f"remeasure after Ctrl-C: exit {rc}, expected 130:\n{screen}"
    written = result_lines(os.path.join(stopped, "results"))
    check_same_as_daemon(daemon, stopped, sequences=sorted(written))
    c = json.load(open(os.path.join(stopped, "comparison.json")))
    assert 1 <= len(written) < len(parts) and c["parts"] == len(written), (len(written), c)
    assert sorted(written) == sorted(parts)[:len(written)], \
        f"written {sorted(written)}: not the first parts in order"
    assert "Stopped before the end" in open(os.path.join(stopped, "remeasure.html")).read()
    print(f"remeasure stopped by Ctrl-C after part 1: exit 130, the first {len(written)} of "
          f"{len(parts)} parts written, each equal to the daemon's, the page says it was stopped")
    check_bad_input(hotgauge, daemon, results_dir, workdir)


def check_bad_input(hotgauge, daemon, results_dir, workdir):
    """A part whose archived recording is gone is listed with why and the others are measured;
    a recipe of another part is refused naming both; --out on the results read is refused."""
    lost = min(s for s, j in daemon.items() if "verification" not in j)
    copy = os.path.join(workdir, "results-one-lost")
    os.makedirs(copy)
    for path in glob.glob(os.path.join(results_dir, "*.jsonl")):
        with open(path) as f, open(os.path.join(copy, os.path.basename(path)), "w") as out:
            for text in f:
                j = json.loads(text)
                if j["sequence"] == lost:
                    j["archived_as"] = j["archived_as"] + ".deleted-for-the-quota"
                out.write(json.dumps(j) + "\n")
    out_dir = os.path.join(workdir, "remeasure-one-lost")
    r = subprocess.run([hotgauge, "remeasure", copy, "--out", out_dir, "--recipe", RECIPE],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, f"remeasure with a recording gone: exit {r.returncode}: {r.stderr}"
    c = json.load(open(os.path.join(out_dir, "comparison.json")))
    left = {n["sequence"]: n["why"] for n in c["not_remeasured"]}
    parts = [s for s, j in daemon.items() if "verification" not in j]
    assert list(left) == [lost] and "gone" in left[lost], left
    assert c["parts"] == len(parts) - 1 == c["unchanged"], c
    print(f"remeasure with part {lost}'s recording gone: listed ({left[lost][-60:]}), the other "
          f"{c['parts']} measured")

    with open(RECIPE) as f:
        other = yaml.safe_load(f)
    other["part"] = "hub-z"
    other_path = os.path.join(workdir, "hub-z.yaml")
    with open(other_path, "w") as f:
        yaml.safe_dump(other, f, sort_keys=False)
    r = subprocess.run([hotgauge, "remeasure", results_dir, "--out",
                        os.path.join(workdir, "remeasure-hub-z"), "--recipe", other_path],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 1 and "hub-z" in r.stderr and "hub-a" in r.stderr, \
        f"another part's recipe: exit {r.returncode}, {r.stderr}"
    r = subprocess.run([hotgauge, "remeasure", results_dir, "--out",
                        os.path.dirname(os.path.abspath(results_dir)), "--recipe", RECIPE],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 1 and "give --out another folder" in r.stderr, r.stderr
    print("remeasure refuses another part's recipe naming both, and --out on the results read")
