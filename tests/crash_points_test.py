#!/usr/bin/python3
"""Results that survive any crash (issue 39, docs/results.md "One commit per part"), on the
virtual line (tests/virtual_line.py) with a real Mosquitto broker and subscriber, loopback only.

hotgauged is stopped at every file operation of a part, in turn: killed (SIGKILL) just before the
operation, and, separately, with the disk full from that operation on (then killed once the part
has ended, as an operator freeing space would restart it). The point is picked by an LD_PRELOAD
shim (tests/crash_shim.c: a glob on the file's path, the operation, the mode), armed by a file
that the test creates just before the part, so the start's own writes pass. The points:

  .sequence write and sync (the number reserved), the day's JSON line write and sync (the
  commit), the CSV row's write and sync (after the PLC's registers), the archive's .partial folder, a file in it, their sync and the rename,
  the plant spool's append and sync, and, after the broker's acknowledgement, spool.last and
  spool.cursor (on the publisher's thread: the part before's, or this one's).

After every restart, before anything else, the files are checked:
  - JSON sequences strictly increasing; the CSV rows the same parts (sequence, part id, verdict);
  - every line's archive folder there, whole (part.yaml) or with NOT_ARCHIVED.txt, no .partial
    left, no folder that no line names;
  - the subscriber has every committed line, byte for byte, and nothing else;
  - PLC input 5 = the last committed sequence.
Then the PLC triggers the interrupted part again (same part id) unless it saw DONE: a part whose
result committed gets that result again (same sequence, no new line); one whose result never
committed is measured under a new number, above every number used before, its line and row
saying `remeasure_of` the number it lost. Last, a part whose DONE the PLC acknowledged, a kill
while idle and the same part id triggered again: measured anew (a repeat, not a re-show).

    /usr/bin/python3 crash_points_test.py BUILD_DIR SHIM
"""
import csv
import glob
import json
import os
import shutil
import signal
import sys
import tempfile
import time

import yaml

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import virtual_line as vl  # noqa: E402
import plant_data_test as pdt  # noqa: E402

BIN_DIR, SHIM = os.path.abspath(sys.argv[1]), os.path.abspath(sys.argv[2])
ADDRESS = "127.0.0.27"  # this test's own camera
pdt.BROKER = "127.0.0.28"  # and broker

# (name, glob on the path, operation, committed before it): the part's file operations in order.
# spool.last and spool.cursor are written by the publisher's thread once the broker acknowledged
# a result: that may be the part before's, so whether the part committed first is not known.
POINTS = [
    ("sequence write", "*/results/.sequence", "write", False),
    ("sequence sync", "*/results/.sequence", "sync", False),
    ("JSON line write", "*/results/[0-9]*.jsonl", "write", False),
    ("JSON line sync", "*/results/[0-9]*.jsonl", "sync", False),
    ("CSV row write", "*/results/[0-9]*.csv", "write", True),
    ("CSV row sync", "*/results/[0-9]*.csv", "sync", True),
    ("archive folder", "*/archive/*.partial", "mkdir", True),
    ("archive file", "*/archive/*.partial/*", "write", True),
    ("archive sync", "*/archive/*.partial*", "sync", True),
    ("archive rename", "*/archive/*.partial", "rename", True),
    ("spool write", "*/spool/spool.jsonl", "write", True),
    ("spool sync", "*/spool/spool.jsonl", "sync", True),
    ("spool last", "*/spool/spool.last.tmp", "write", None),
    ("spool cursor", "*/spool/spool.cursor.tmp", "write", None),
]


def committed(line):
    out = []
    for path in sorted(glob.glob(os.path.join(line.results_dir, "[0-9]*.jsonl"))):
        with open(path) as f:
            out += [t.rstrip("\n") for t in f if t.endswith("\n")]
    return out


def check_files(line, sub, plc):
    """The invariants, after a restart; returns the committed lines as JSON."""
    texts = committed(line)
    parts = [json.loads(t) for t in texts]
    seqs = [p["sequence"] for p in parts]
    assert seqs == sorted(set(seqs)), f"JSON sequences not strictly increasing: {seqs}"
    rows = []
    for path in sorted(glob.glob(os.path.join(line.results_dir, "*.csv"))):
        with open(path, newline="") as f:
            rows += list(csv.DictReader(f))
    got = sorted((int(r["sequence"]), r["part_id"], r["verdict"], r["remeasure_of"]) for r in rows)
    want = [(p["sequence"], p["part"]["part_id"], p["part"]["verdict"],
             str(p.get("remeasure_of") or "")) for p in parts]
    assert got == want, f"CSV rows {got} != JSON lines {want}"
    named = set()
    for p in parts:
        if p["archived_as"] is None:
            continue
        where = p["archived_as"]
        named.add(os.path.normpath(where))
        whole = os.path.exists(os.path.join(where, "part.yaml"))
        noted = os.path.exists(os.path.join(where, "NOT_ARCHIVED.txt"))
        assert whole != noted, f"seq {p['sequence']}: {where}: whole {whole}, noted {noted}"
    folders = {os.path.normpath(d) for d in glob.glob(os.path.join(line.archive_dir, "*", "*"))}
    assert not [d for d in folders if d.endswith(".partial")], f"left over: {folders}"
    assert folders == named, f"archive folders {folders - named} named by no line, " \
                             f"{named - folders} missing"
    by_seq = dict(zip(seqs, texts))
    vl.wait_for(lambda: set(by_seq) <= {json.loads(t)["sequence"] for t in sub.results()},
                "every committed result at the broker", 30)
    for t in sub.results():
        s = json.loads(t)["sequence"]
        assert by_seq.get(s) == t, f"the broker got sequence {s}, which is not the committed line"
    r = vl.decode(plc.inputs())
    assert r["sequence"] == (seqs[-1] if seqs else 0) & 0xFFFF, \
        f"input 5 reads {r['sequence']}, the last committed is {seqs[-1:]}"
    return parts


def settled(line, part_id):
    """The part's last file operations done: its log line follows its archive."""
    line.daemon.wait_line(r"part %d(: | seq \d+ recipe)" % part_id, 30)


def reserved(line):
    with open(os.path.join(line.results_dir, ".sequence")) as f:
        return int(f.read().split()[0])


def start_daemon(line, point, mode):
    name, pattern, op, _ = point
    line.daemon_env = {"LD_PRELOAD": SHIM, "HG_CRASH_GLOB": pattern, "HG_CRASH_OP": op,
                       "HG_CRASH_MODE": mode, "HG_CRASH_ROOT": line.workdir,
                       "HG_CRASH_ARM": os.path.join(line.workdir, "arm")}
    line.start_daemon()


def crash(line, plc, conveyor, point, mode, part_id):
    """One part with the point armed; returns (the PLC's last state, its sequence if DONE)."""
    name, _, _, _ = point
    open(os.path.join(line.workdir, "arm"), "w").close()
    conveyor.load(1)
    try:
        plc.to_idle()
        plc.trigger(part_id)
    except Exception:  # killed before it answered: the sequence's points, or the publisher's
        pass  # thread acknowledging the part before's result (spool.last, spool.cursor)
    deadline = time.monotonic() + 60
    state, seq = None, None
    while time.monotonic() < deadline:
        if line.daemon.proc.poll() is not None:
            break
        try:
            r = vl.decode(plc.inputs())
            state, seq = r["state"], r["sequence"]
        except Exception:  # the connection went with the daemon
            pass
        if mode == "full" and state in (vl.DONE, vl.FAULT):
            break
        time.sleep(0.02)
    rc = line.daemon.proc.poll()
    if mode == "full":  # the archive and the spool come after DONE: armed until they are done
        assert rc is None, f"{name}, disk full: hotgauged exited ({rc})"
        settled(line, part_id)
        line.daemon.wait_line("No space left on device", 20)
    os.unlink(os.path.join(line.workdir, "arm"))
    if mode == "kill":
        assert rc == -signal.SIGKILL, f"{name}: the point was never reached (state {state})"
    else:
        line.daemon.proc.kill()
        line.daemon.proc.wait(10)
    return state, seq


def taken_then_killed(line, plc, conveyor, part_id):
    """A part measured and its DONE acknowledged, hotgauged killed while idle, restarted: the same
    part id triggered again (a repeat measurement) is measured anew, not shown the old result."""
    r = vl.run_part(plc, conveyor, 1, part_id)  # acknowledges DONE
    assert r["state"] == vl.DONE, r
    vl.wait_for(lambda: open(os.path.join(line.results_dir, ".sequence")).read().split()[3] == "D",
                ".sequence marked D once the PLC took the result", 10)
    line.daemon.proc.kill()
    line.daemon.proc.wait(10)
    line.start_daemon()
    plc2 = vl.Plc(line.plc_port)
    try:
        again = vl.run_part(plc2, conveyor, 1, part_id)
        assert again["state"] == vl.DONE and again["sequence"] == (r["sequence"] + 1) & 0xFFFF, \
            f"triggered again: seq {again['sequence']}, the first was {r['sequence']}"
        settled(line, part_id)
        last = committed(line)[-1]
        assert json.loads(last).get("remeasure_of") is None, "a repeat is not a re-measurement"
    finally:
        plc2.close()


def killed_twice(line, plc, sub, conveyor, part_id):
    """Killed after a part's commit, restarted, killed again while idle before the PLC triggered
    the part again, restarted: the part triggered again is still shown its committed result."""
    csv_row = next(p for p in POINTS if p[0] == "CSV row write")
    plc.close()
    line.daemon.proc.kill()
    line.daemon.proc.wait(10)
    start_daemon(line, csv_row, "kill")
    plc = vl.Plc(line.plc_port)
    crash(line, plc, conveyor, csv_row, "kill", part_id)
    plc.close()
    for _ in range(2):  # the restart after the crash, and the one after a kill while idle
        line.start_daemon()
        plc = vl.Plc(line.plc_port)
        parts = check_files(line, sub, plc)
        plc.close()
        line.daemon.proc.kill()
        line.daemon.proc.wait(10)
    line.start_daemon()
    plc = vl.Plc(line.plc_port)
    mine = [p for p in parts if p["part"]["part_id"] == str(part_id)]
    assert len(mine) == 1, f"part {part_id}: {len(mine)} lines"
    r = vl.run_part(plc, conveyor, 1, part_id)
    assert r["state"] == vl.DONE and r["sequence"] == mine[0]["sequence"] & 0xFFFF, \
        f"after two restarts: seq {r['sequence']}, committed {mine[0]['sequence']}"
    assert json.loads(committed(line)[-1])["sequence"] == mine[0]["sequence"], "measured again"
    return plc


def main():
    workdir = tempfile.mkdtemp(prefix="hotgauge-crash-")
    line = vl.Line(BIN_DIR, workdir, ADDRESS, archive_every_nth_ok=1)
    broker = pdt.Broker(workdir, vl.free_port()).start()
    spool = os.path.join(workdir, "spool")
    line.config_extra = pdt.mqtt_config(workdir, broker, pdt.PASSWORD).replace(
        "  keepalive_s:", f"  spool_dir: {spool}\n  keepalive_s:")
    sub = pdt.Subscriber(broker, "crash-points")
    line.start_pty()
    line.start_cell()
    line.write_config()
    # One face a part (the points, not the measurement): the recipe's features on the top face
    # alone, as the daemon refuses a feature on a face it does not scan.
    with open(os.path.join(vl.REPO, "config/parts/hub-a.yaml")) as f:
        recipe = yaml.safe_load(f)
    recipe["features"] = [x for x in recipe["features"] if x["faces"] == ["top"]]
    top_recipe = os.path.join(workdir, "hub-a-top.yaml")
    with open(top_recipe, "w") as f:
        yaml.safe_dump(recipe, f, sort_keys=False)
    with open(line.config_path) as f:
        text = f.read().replace("faces: [top, bottom, side1, side2]", "faces: [top]").replace(
            os.path.join(vl.REPO, "config/parts/hub-a.yaml"), top_recipe)
    with open(line.config_path, "w") as f:
        f.write(text)
    failures, used, part_id = [], set(), 7000
    try:
        cases = [(p, m) for p in POINTS for m in ("kill", "full")]
        start_daemon(line, cases[0][0], cases[0][1])
        plc, conveyor = vl.Plc(line.plc_port), vl.Conveyor(line.axis_port)
        check_files(line, sub, plc)
        for i, (point, mode) in enumerate(cases):
            label = f"{point[0]}, {'killed' if mode == 'kill' else 'disk full'}"
            part_id += 1
            before = {p["sequence"] for p in check_files(line, sub, plc)}
            try:
                state, seq = crash(line, plc, conveyor, point, mode, part_id)
            except (AssertionError, TimeoutError, RuntimeError) as e:
                failures.append(f"{label}: {e}")
                break  # the daemon's state is unknown: the rest would not say more
            lost = reserved(line)  # the number the part was given (or the one before)
            used |= before | {lost}
            nxt = cases[i + 1] if i + 1 < len(cases) else cases[0]
            plc.close()
            start_daemon(line, nxt[0], nxt[1])
            plc = vl.Plc(line.plc_port)
            try:
                parts = check_files(line, sub, plc)
                mine = [p for p in parts if p["part"]["part_id"] == str(part_id)]
                assert len(mine) <= 1, f"part {part_id} committed twice"
                if mine:
                    # killed before the JSON line's sync: written, so committed (a kill, not a
                    # power cut)
                    assert point[3] is not False or (mode, point[0]) == ("kill", "JSON line sync"), \
                        "committed although stopped before the commit"
                elif point[3]:
                    raise AssertionError("stopped after the commit, yet no line")
                if state == vl.DONE:
                    print(f"{label}: the PLC saw DONE (seq {seq}); files consistent", flush=True)
                    continue
                # The PLC triggers the part again.
                r = vl.run_part(plc, conveyor, 1, part_id)
                assert r["state"] == vl.DONE, f"the part again: {r['state']} {r.get('error')}"
                if not mine:
                    settled(line, part_id)
                after = check_files(line, sub, plc)
                if mine:  # committed: its result again, not a new measurement
                    assert r["sequence"] == mine[0]["sequence"] & 0xFFFF, \
                        f"published {r['sequence']}, committed {mine[0]['sequence']}"
                    assert after[-1]["sequence"] == mine[0]["sequence"], "measured again"
                    print(f"{label}: committed as seq {mine[0]['sequence']}, published again "
                          "after the restart", flush=True)
                else:
                    new = after[-1]
                    assert new["part"]["part_id"] == str(part_id)
                    assert new["sequence"] > max(used), \
                        f"seq {new['sequence']} reuses a number (used up to {max(used)})"
                    numbered = lost > max(before | {0})  # stopped after its number was kept
                    assert new.get("remeasure_of") == (lost if numbered else None), \
                        f"remeasure_of {new.get('remeasure_of')}, the part lost {lost}"
                    used.add(new["sequence"])
                    print(f"{label}: not committed ("
                          f"{f'seq {lost} lost' if numbered else 'stopped before it had a number'}"
                          f"), measured again as seq {new['sequence']}", flush=True)
            except (AssertionError, TimeoutError) as e:
                failures.append(f"{label}: {e}")
                print(f"{label}: FAILED: {e}", flush=True)
        if not failures:
            try:
                taken_then_killed(line, plc, conveyor, part_id + 1)
                print("killed while idle after the PLC took a part's result: the same part "
                      "triggered again is measured anew", flush=True)
                plc = killed_twice(line, plc, sub, conveyor, part_id + 2)
                print("killed after a commit, then again while idle before the part came back: "
                      "it is still shown its committed result", flush=True)
            except (AssertionError, TimeoutError) as e:
                failures.append(f"after the points: {e}")
        plc.close()
        conveyor.close()
    finally:
        sub.close()
        rc = line.daemon.stop() if getattr(line, "daemon", None) else None  # SIGTERM: exit 0
        line.stop()
        broker.stop()
    if failures or rc != 0:
        vl.print_logs(workdir)
        print("FAILED:\n  " + "\n  ".join(failures) + f"\nhotgauged's exit status {rc}")
        return 1
    print(f"{len(cases)} crash points: the files agree after every restart")
    shutil.rmtree(workdir, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
