#!/usr/bin/python3
"""hotgauged under faults, on the virtual line (tests/virtual_line.py), loopback only.

One daemon lives through, in turn:
  1. a good part;
  2. the PLC dropping its connection mid-handshake (BUSY): the result waits for it, valid;
  3. the accelerometer stream stopped: the part is measured and flagged degraded;
  4. a recipe with a slot past the register map's 16, then a broken config, sent with SIGHUP:
     each rejected naming the feature or the line, the old one kept, the next part measured;
  5. the results directory full (RLIMIT_FSIZE on the daemon): PLC fault 206, nothing half written;
  6. the camera (the whole virtual cell) killed mid-part: PLC fault 203; after it is back, the
     next part is measured;
  6b. the camera restarted between parts, triggered at once, its first scan missing its first
      frames: that face scanned again, measured;
  7. hotgauged killed (kill -9) while IDLE and restarted 1 s later: the camera is taken back
     once the dead process's control channel expires, the next part is measured, and the PLC's
     result sequence goes on from the results files; killed mid-part: the part triggered again
     is measured;
  8. a face whose two scans both miss their first frames: left out, its features not measured,
     the others degraded (a pose found without it), no NOK;
and after each, the daemon still runs and no earlier result is lost from the files.

    /usr/bin/python3 daemon_faults_test.py BUILD_DIR
"""
import json
import re
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import virtual_line as vl  # noqa: E402

BIN_DIR = sys.argv[1]
ADDRESS = "127.0.0.8"  # this test's own camera address


def wait_health(plc, bits, what, timeout, clear=False):
    """The PLC's device-health register (input 113) with `bits` set (or clear), bounded."""
    def seen():
        r = vl.decode(plc.inputs())
        return r if ((r["health"] & bits) == 0) == clear else None
    return vl.wait_for(seen, what, timeout)


class UdpRelay(vl.DatagramReceiver):
    """Passes the accelerometer's datagrams on to the daemon while `on`."""

    def __init__(self, to_port):
        self.tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.to = ("127.0.0.1", to_port)
        self.on = True
        super().__init__(socket.AF_INET, ("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]

    def on_datagram(self, data):
        if self.on:
            self.tx.sendto(data, self.to)


def jsonl(line):
    out = []
    for name in sorted(os.listdir(line.results_dir)):
        if name.endswith(".jsonl"):
            with open(os.path.join(line.results_dir, name)) as f:
                out += [json.loads(t) for t in f]
    return out


def csv_rows(line):
    n = 0
    for name in sorted(os.listdir(line.results_dir)):
        if name.endswith(".csv"):
            with open(os.path.join(line.results_dir, name)) as f:
                n += sum(1 for _ in f) - 1
    return n


def alive(line):
    assert line.daemon.proc.poll() is None, f"hotgauged died:\n{line.daemon.text()[-3000:]}"


def step(title):
    print(f"--- {title}", flush=True)


def main():
    workdir = tempfile.mkdtemp(prefix="hotgauge-faults-")
    line = vl.Line(BIN_DIR, workdir, ADDRESS, seed=11)
    relay = None
    ok = False
    try:
        line.start_pty()
        relay = UdpRelay(line.accel_port)
        line.start_cell(accel_to=f"127.0.0.1:{relay.port}")
        line.write_config()
        good_config = open(line.config_path).read()
        line.start_daemon()
        plc, conveyor = vl.Plc(line.plc_port), vl.Conveyor(line.axis_port)
        n = 0
        kept = []  # JSON lines so far: must never shrink or change

        def part(expect_state=vl.DONE):
            nonlocal n
            n += 1
            p = vl.run_part(plc, conveyor, n, 500 + n)
            state = "DONE" if p["state"] == vl.DONE else f"FAULT {p['error']}"
            print(f"part {n}: {state}, verdict {p['verdict']}, cycle {p['cycle_s']:.1f} s",
                  flush=True)
            assert p["state"] == expect_state, p
            return p

        def expect_ok(p):
            """The part is OK with all 14 features; if not, the results file's reasons say why."""
            if p["verdict"] != "OK" or p["n_features"] != 14:
                last = jsonl(line)[-1]
                raise AssertionError(f"expected OK, got {p['verdict']}: PLC {p}; results file "
                                     f"{last['part'].get('degraded_reasons')}")

        def start_part(k):
            conveyor.load(k)
            plc.to_idle()
            plc.trigger(500 + k)

        def kill_cell():
            line.cell.proc.kill()
            line.cell.proc.wait()
            line.procs.remove(line.cell)

        def start_cell_again(name):
            """The virtual cell started again (its log under `name`); the conveyor on it."""
            line.cell.name = name
            line.start_cell()
            return vl.Conveyor(line.axis_port)

        def files_intact():
            now = jsonl(line)
            assert now[:len(kept)] == kept, "an earlier result changed or vanished"
            kept[:] = now
            assert csv_rows(line) == len(now), f"{csv_rows(line)} CSV rows, {len(now)} JSON lines"

        step("1. a good part")
        p = part()
        expect_ok(p)
        files_intact()

        step("2. the PLC drops its connection while BUSY, then comes back")
        n += 1
        start_part(n)
        plc.wait_state({vl.BUSY}, 5)
        plc.close()
        time.sleep(3)
        plc = vl.Plc(line.plc_port)
        r = vl.decode(plc.wait_state({vl.DONE, vl.FAULT}, 60))
        assert r["state"] == vl.DONE and r["part_id"] == 500 + n, r
        assert r["verdict"] == "OK" and all(f["um"] is not None for f in r["features"].values()), r
        plc.to_idle()
        alive(line)
        files_intact()
        assert kept[-1]["part"]["part_id"] == str(500 + n)

        step("3. the accelerometer stream stops")
        relay.on = False
        silent = wait_health(plc, 0b10, "the accelerometer's health bit", 2.0)
        print(f"   PLC device health {silent['health']:#x} (accelerometer) after relay off")
        p = part()
        last = jsonl(line)[-1]["part"]
        # The PLC's reason bits say what the results file says, feature by feature.
        bits = vl.check_reasons(p, jsonl(line)[-1])
        print(f"   PLC reasons: part {bits:#x}, features "
              f"{ {s: f['reasons'] for s, f in p['features'].items() if f['reasons']} }")
        assert bits & vl.DEGRADED_BIT, f"a degraded part without the degraded reason: {bits:#x}"
        print("   degraded:", last["degraded_reasons"][:2])
        assert last["degraded"], "no accelerometer: the part must be flagged degraded"
        assert any("accelerometer" in why for why in last["degraded_reasons"]), last
        # Uncompensated, a feature may also come out NOK or not measured; never plain OK.
        assert p["verdict"] in ("DEGRADED", "NOK", "NOT_MEASURED"), p["verdict"]
        # A degraded part's recording is archived, and `hotgauge measure` gets the same numbers
        # from it: the daemon and the tool run one pipeline.
        archived = jsonl(line)[-1]["archived_as"]
        # Written after the result is published; part.yaml comes last.
        vl.wait_for(lambda: os.path.exists(os.path.join(archived, "part.yaml")), "the archive", 30)
        again = json.loads(subprocess.run(
            [os.path.join(BIN_DIR, "src/app/hotgauge"), "measure", archived, "--json"],
            check=True, capture_output=True, text=True).stdout)
        for f, g in zip(last["features"], again["features"]):
            assert f["name"] == g["name"] and f["verdict"] == g["verdict"], (f, g)
            same = f["cold_mm"] == g["cold_mm"] or abs(f["cold_mm"] - g["cold_mm"]) < 1e-9
            assert same, (f, g)
        print(f"   re-measured {archived}: all {len(again['features'])} features identical")
        relay.on = True
        wait_health(plc, 0b10, "the accelerometer back", 3.0, clear=True)
        alive(line)
        files_intact()

        step("4. a broken config with SIGHUP")
        # First a recipe the cell cannot run (issue 40): a slot past the register map's 16. The
        # reload is refused naming the feature, and the part after is measured with the old one.
        with open(os.path.join(vl.REPO, "config/parts/hub-a.yaml")) as f:
            slot17 = f.read().replace("slot: 14", "slot: 17", 1)
        bad_recipe = os.path.join(line.workdir, "hub-a-slot17.yaml")
        with open(bad_recipe, "w") as f:
            f.write(slot17)
        with open(line.config_path, "w") as f:
            f.write(good_config.replace(os.path.join(vl.REPO, "config/parts/hub-a.yaml"),
                                        bad_recipe))
        line.daemon.proc.send_signal(signal.SIGHUP)
        line.daemon.wait_line(r"reload REJECTED.*feature 'Die shift': slot 17 is outside 1\.\.16",
                              10)
        alive(line)
        expect_ok(part())  # 14 features: the old recipe's
        with open(line.config_path, "w") as f:
            f.write(good_config.replace("camera:", "camera: [unclosed\n  id:", 1))
        line.daemon.proc.send_signal(signal.SIGHUP)
        line.daemon.wait_line(r"reload REJECTED", 10)
        alive(line)
        p = part()
        expect_ok(p)
        # systemctl status shows STATUS=: after the part, idle again (the daemon says so within
        # its loop period of the PLC's acknowledgement), the rejection still in it (issue 39: it
        # had been overwritten in the same millisecond).
        deadline = time.monotonic() + 5
        while not line.notify.values("STATUS")[-1][1].startswith("idle"):
            assert time.monotonic() < deadline, line.notify.values("STATUS")[-3:]
            time.sleep(0.05)
        status = [v for _, v in line.notify.values("STATUS")]
        assert "reload rejected at" in status[-1], status[-3:]
        assert re.search(r"hotgauged\.yaml:\d+", status[-1]), status[-1]  # the file and line
        with open(line.config_path, "w") as f:
            f.write(good_config)
        line.daemon.proc.send_signal(signal.SIGHUP)
        line.daemon.wait_line(r"reloaded: config hash", 10)
        deadline = time.monotonic() + 5
        while "reload rejected" in line.notify.values("STATUS")[-1][1]:
            assert time.monotonic() < deadline, line.notify.values("STATUS")[-3:]
            time.sleep(0.05)
        print(f"   STATUS= after the rejected reload and a part: {status[-1][:100]}...")
        files_intact()

        step("5. the results directory is full")
        big = max(os.path.getsize(os.path.join(line.results_dir, f))
                  for f in os.listdir(line.results_dir))
        pid = str(line.daemon.proc.pid)
        subprocess.run(["prlimit", "--pid", pid, f"--fsize={big}:unlimited"], check=True)  # soft only
        p = part(expect_state=vl.FAULT)
        assert p["error"] == 206, p
        alive(line)
        files_intact()  # nothing half written, nothing lost
        subprocess.run(["prlimit", "--pid", pid, "--fsize=unlimited"], check=True)
        p = part()
        expect_ok(p)
        files_intact()

        step("6. the camera is killed mid-part")
        n += 1
        start_part(n)
        time.sleep(1.5)  # inside the first face's scan
        assert plc.state() == vl.BUSY
        kill_cell()
        conveyor.close()
        r = vl.decode(plc.wait_state({vl.DONE, vl.FAULT}, 30))
        print(f"   PLC: state {r['state']} error {r['error']}")
        assert r["state"] == vl.FAULT and r["error"] == 203, r
        alive(line)
        files_intact()
        assert kept[-1]["part"]["part_id"] == str(500 + n), "the failed part has its row"
        assert kept[-1]["part"]["verdict"] == "NOT_MEASURED"
        conveyor = start_cell_again("virtual-cell-killed")
        p = part()
        expect_ok(p)
        files_intact()

        step("6b. the camera restarts between parts; the PLC triggers at once")
        # The daemon's session still holds the old device, and Aravis's heartbeat may not have
        # noticed yet: the control register says the camera no longer knows us (the soak saw
        # FAULT 203 in 4 of 11 such restarts, then a part scanned from a stale acquisition).
        # The restarted camera also loses the first 7 frames of its first scan (finding 8:
        # positions count from a scan's first frame, so that scan would be 14 mm off, and the
        # soak saw such a part published NOK): the face is scanned again.
        conveyor.close()
        plc.to_idle()
        killed = time.monotonic()
        kill_cell()
        # IDLE, nothing triggered: the camera's loss shows in the health register all the same.
        r = wait_health(plc, 0b1, "the camera's health bit after the kill", 2.0)
        print(f"   camera killed while IDLE: PLC device health {r['health']:#x} after "
              f"{time.monotonic() - killed:.2f} s (state {r['state']})")
        assert r["state"] == vl.IDLE, r["state"]
        line.cell_extra = ["--lose-scan-start", "7", "--lose-scan-start-count", "1"]
        conveyor = start_cell_again("virtual-cell-restarted")
        p = part()
        expect_ok(p)
        line.daemon.wait_line(r"face top: the scan lost its start \(.*\); scanning it again", 5)
        files_intact()

        def kill_and_restart(tag):
            """kill -9, then a restart 1 s later as systemd would (RestartSec)."""
            line.daemon.proc.kill()
            line.daemon.proc.wait()
            line.procs.remove(line.daemon)
            line.daemon.log.close()
            os.rename(line.daemon.log_path, line.daemon.log_path.replace(".log", f"-{tag}.log"))
            time.sleep(1.0)
            line.start_daemon()
            return vl.Plc(line.plc_port)

        step("7. hotgauged killed (kill -9) while IDLE and restarted 1 s later")
        # The dead process holds the camera's control channel until its heartbeat expires; the
        # new one waits for it (camera.control_wait_ms). The PLC's sequence goes on from the
        # results files (issue 18, findings 3 and 4).
        last = kept[-1]["sequence"]
        plc.close()
        plc = kill_and_restart("killed-idle")
        r = vl.decode(plc.inputs())
        print(f"   after the restart: state {r['state']}, sequence {r['sequence']} "
              f"(files: {last})")
        assert r["state"] == vl.IDLE and r["sequence"] == last & 0xFFFF, r
        p = part()
        expect_ok(p)
        files_intact()
        assert kept[-1]["sequence"] == last + 1, kept[-1]["sequence"]
        assert p["sequence"] == (last + 1) & 0xFFFF, p

        step("7a. a part that faults 206, then a restart: its sequence number is not used again")
        # Issue 39: the next number was read from the files, which the 206 part never reached,
        # so the journal's SEQ= named two parts. The numbers used are kept in results/.sequence.
        big = max(os.path.getsize(os.path.join(line.results_dir, f))
                  for f in os.listdir(line.results_dir))
        subprocess.run(["prlimit", "--pid", str(line.daemon.proc.pid), f"--fsize={big}:unlimited"],
                       check=True)
        p = part(expect_state=vl.FAULT)
        assert p["error"] == 206, p
        files_intact()
        last = kept[-1]["sequence"]
        # The part's journal line (written after the registers): the number it used.
        used = int(line.daemon.wait_line(rf"part {500 + n} seq (\d+) recipe \S+: FAULT 206",
                                         10).group(1))
        assert used == last + 1, (used, last)
        plc.close()
        plc = kill_and_restart("killed-after-206")
        r = vl.decode(plc.inputs())
        assert r["sequence"] == last & 0xFFFF, r  # input 5: the last committed part
        p = part()
        expect_ok(p)
        files_intact()
        print(f"   the 206 part used seq {used}; after the restart the next part is "
              f"seq {kept[-1]['sequence']}")
        assert kept[-1]["sequence"] == used + 1, (kept[-1]["sequence"], used)

        step("7b. hotgauged killed (kill -9) mid-part; the PLC triggers the part again")
        # The dead process also left the camera acquiring: the new one stops that acquisition
        # before its own, or the retried part's first face is scanned past the part (the soak
        # saw it NOT_MEASURED with the top face 100 % NaN).
        n += 1
        start_part(n)
        time.sleep(1.5)  # inside the first face's scan
        plc.close()
        plc = kill_and_restart("killed-busy")
        p = vl.run_part(plc, conveyor, n, 500 + n)
        print(f"   part {n} again: verdict {p['verdict']}, cycle {p['cycle_s']:.1f} s")
        assert p["state"] == vl.DONE and p["verdict"] == "OK" and p["n_features"] == 14, p
        files_intact()
        assert kept[-1]["part"]["part_id"] == str(500 + n), "the retried part has its row"

        step("8. a face whose scans lose their first frames twice (finding 8)")
        # Lost every time, the face is left out and its features are not measured: never NOK.
        conveyor.close()
        kill_cell()
        line.cell_extra = ["--lose-scan-start", "7", "--lose-scan-start-count", "2"]
        conveyor = start_cell_again("virtual-cell-lose-start-twice")  # the top face's 2 scans
        p = part()
        last = jsonl(line)[-1]["part"]
        print("   reasons:", last["degraded_reasons"])
        assert p["verdict"] == "NOT_MEASURED", p
        assert any("lost its start twice" in why for why in last["degraded_reasons"]), last
        verdicts = {f["name"]: f["verdict"] for f in last["features"]}
        print("   features:", verdicts)
        assert "NOK" not in verdicts.values(), verdicts
        bits = vl.check_reasons(p, jsonl(line)[-1])
        assert bits & vl.FACE_MISSING, f"a face left out, but the part's reasons are {bits:#x}"
        # The other faces' features are measured, but the pose was found without the top face:
        # degraded, so that they sort nothing. A pose from fewer faces can also leave a narrow
        # face unfit for a plane (Height 1's 0.47 mm bore step, "curved across": once in three
        # fresh-clone runs): not measured, with its reason. Nothing is OK, nothing NOK, and all
        # but that one are measured.
        others = [f for f in last["features"] if "top" not in f["faces"]]
        degraded = [f for f in others if f["verdict"] == "DEGRADED" and f["cold_mm"] is not None
                    and "pose was found without face top" in f["reason"]]
        unmeasured = [f for f in others if f["verdict"] == "NOT_MEASURED" and f["reason"]]
        assert (others and len(degraded) + len(unmeasured) == len(others) and
                len(unmeasured) <= 1), [(f["name"], f["verdict"], f["reason"]) for f in others]
        files_intact()

        step("SIGTERM")
        plc.close()
        conveyor.close()
        t0 = time.monotonic()
        rc = line.daemon.stop(timeout=30)
        print(f"hotgauged exited {rc} in {time.monotonic() - t0:.1f} s")
        assert rc == 0
        seqs = [j["sequence"] for j in kept]
        print("sequences in the files:", seqs)
        assert seqs == sorted(set(seqs)), "sequence numbers repeat or run backwards"
        ok = True
    finally:
        if relay:
            relay.stop = True
        line.stop()
        if not ok:
            vl.print_logs(workdir)
        else:
            shutil.rmtree(workdir, ignore_errors=True)
    print("daemon faults: all passed" if ok else "daemon faults: FAILED")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
