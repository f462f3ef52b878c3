#!/usr/bin/python3
"""The fault soak (issue 18): the virtual line (tests/virtual_line.py) for N parts with faults
injected on a schedule, then a report. Loopback only; every wait is bounded.

    /usr/bin/python3 tests/soak.py --bin-dir build --parts 1000 [--seed 1] [--out DIR]   (make soak)

The line: the virtual cell, hotgauged under a supervisor that behaves like systemd's
Restart=on-failure with RestartSec=2 and WatchdogSec=10 (a daemon that exits or is killed for
any reason is started again 2 s later; one that stops feeding the watchdog gets SIGABRT), the
cell's accelerometer stream passing through a relay that can drop datagrams, and a PLC that
reconnects whenever its connection breaks (every 0.5 s) and, as docs/plc-modbus.md "Across a
restart" says, triggers a part again when a restart took its cycle. Every trigger has its own
part id: part n's k-th attempt is --first-part-id + 10 n + k.

The schedule (deterministic from --seed): parts 1..--first-fault-1 are clean; from there, every
--every parts one fault, the kinds in a seeded order, each kind once per round:
  accel_loss_2/10/30  the relay drops 2, 10 or 30 % of the datagrams, for a run of 3 parts
  accel_outage        the relay passes nothing during one part
  cam_packet_loss     the cell restarted with --packet-loss 0.02 for a run of 3 parts (the
                      restarts in and out of it are camera restarts too)
  cam_restart         the virtual cell (the camera) killed with SIGKILL and started again
                      between parts
  plc_disconnect      the PLC closes its connection 1 s into BUSY and comes back 3 s later
  disk_full           the results files at their size limit (prlimit RLIMIT_FSIZE) for one part
  sighup              a broken config with SIGHUP before one part, the good one before the next
  kill_idle           kill -9 of hotgauged while IDLE, before the part
  kill_busy           kill -9 of hotgauged 0.3-7 s into BUSY; the part is triggered again

Per part: faults, each attempt's PLC state, error, verdict, sequence (input 5) and features,
its results-file row, cycle time (trigger to DONE/FAULT), daemon RSS (idle before the trigger,
once the last part's log line, which follows its archive, is out; and right after the part), the
wall clock's step against the monotonic one over the part, and every feature's error against the
simulator's truth. The checks, reported on stdout and in
OUT/report.json (OUT/parts.jsonl, OUT/rss.csv beside it):
  - no daemon exit but the injected kills (and the final SIGTERM, exit 0);
  - lost: none (every DONE and FAULT has its row, 206 excepted, which has none; every trigger
    ends in DONE or FAULT unless an injected kill took it);
  - duplicated: no sequence, part id or PLC input-5 value twice; JSON lines and CSV rows pair up;
  - reused: no sequence number given to two parts (the daemon logs' "part ID seq N" lines, FAULT
    206 parts included);
  - every DONE matches its row (part id, verdict, feature values to 1 µm, input 5 = the low 16
    bits of its sequence); after a restart, input 5 reads the files' last sequence;
  - false NOK: none (no NOK feature whose true value is within its tolerance), and no trusted
    (OK/NOK) feature off the truth by more than --max-error-mm;
  - every part hit by a fault flagged right: accelerometer loss degraded only with an
    accelerometer reason, outage degraded with one, disk full FAULT 206, a killed cycle no row
    or a NOT_MEASURED one, the others (camera, PLC, SIGHUP, kill while idle) measured as clean
    parts are, with `reload REJECTED` / `reloaded` in the log for SIGHUP; clean parts not
    degraded or not measured;
  - RSS flat: the idle daemon's, median of the last 100 parts within 10 % of parts 100-200
    (N >= 300; a restarted daemon's first parts are in these windows too);
  - a part during which the wall clock stepped more than 1 s (a virtual machine paused and
    resumed): its problems are listed as environment events, not failed (a false NOK still is);
and prints faults by code, verdicts, degraded causes, RSS per daemon lifetime and cycle times.
Exit status 0 when every check passes.
"""
import argparse
import collections
import csv
import json
import logging
import os
import random
import re
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import virtual_line as vl  # noqa: E402
from pymodbus.client import ModbusTcpClient  # noqa: E402

CLOCK_STEP_S = 1.0  # a part during which the wall clock stepped more than this: environment
KINDS = ("accel_loss_2", "accel_loss_10", "accel_loss_30", "accel_outage", "cam_packet_loss",
         "cam_restart", "plc_disconnect", "disk_full", "sighup", "kill_idle", "kill_busy")
RUN_LENGTH = {"accel_loss_2": 3, "accel_loss_10": 3, "accel_loss_30": 3, "cam_packet_loss": 3,
              "sighup": 2}
ACCEL_LOSS = {"accel_loss_2": 0.02, "accel_loss_10": 0.10, "accel_loss_30": 0.30}
PACKET_LOSS = 0.02
RESTART_S = 2.0     # RestartSec
WATCHDOG_S = 10.0   # WatchdogSec, as config/hotgauged.service
CYCLE_TIMEOUT_S = 180
RECONNECT_TIMEOUT_S = 120


# ---------------------------------------------------------------- the line's pieces

class LossyRelay(vl.DatagramReceiver):
    """The accelerometer stream on its way to the daemon: drops a seeded fraction `loss` of the
    datagrams, or all of them while not `on`."""

    def __init__(self, to_port, seed):
        self.tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.to = ("127.0.0.1", to_port)
        self.on, self.loss = True, 0.0
        self.rng = random.Random(seed)
        self.passed = self.dropped = 0
        super().__init__(socket.AF_INET, ("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]

    def on_datagram(self, data):
        if self.on and self.rng.random() >= self.loss:
            self.tx.sendto(data, self.to)
            self.passed += 1
        else:
            self.dropped += 1


class SoakLine(vl.Line):
    """The virtual line with a camera link that may drop packets (`packet_loss`)."""
    packet_loss = 0.0
    cell_restarts = 0

    def cell_argv(self, accel_to):
        extra = ["--packet-loss", str(self.packet_loss)] if self.packet_loss else []
        return super().cell_argv(accel_to) + extra

    def restart_cell(self, packet_loss=None):
        """Kills the cell (SIGKILL: the camera's power cut) and starts it again."""
        self.cell.proc.kill()
        self.cell.proc.wait()
        self.cell.log.close()
        self.procs.remove(self.cell)
        self.cell_restarts += 1
        os.rename(self.cell.log_path, self.cell.log_path[:-4] + f".{self.cell_restarts}.log")
        if packet_loss is not None:
            self.packet_loss = packet_loss
        self.start_cell()


class Supervisor:
    """hotgauged as systemd runs it: Type=notify, Restart=on-failure, RestartSec=2,
    WatchdogSec=10. Each lifetime logs to hotgauged.N.log."""

    def __init__(self, line):
        self.line = line
        self.notify = vl.NotifySocket(os.path.join(line.workdir, "notify"))
        self.lives = []  # one dict per daemon process
        self.lock = threading.Lock()
        self.stopping = False
        self.start_daemon()
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    @property
    def life(self):
        return self.lives[-1]

    def start_daemon(self):
        gen = len(self.lives) + 1
        env = {"NOTIFY_SOCKET": self.notify.path, "WATCHDOG_USEC": str(int(WATCHDOG_S * 1e6))}
        argv = [os.path.join(self.line.bin_dir, "src/daemon/hotgauged"), "--config",
                self.line.config_path]
        proc = vl.Process(f"hotgauged.{gen}", argv, self.line.workdir, env)
        self.lives.append({"gen": gen, "pid": proc.proc.pid, "proc": proc, "planned": None,
                           "started": time.monotonic(), "notify_from": len(self.notify.messages),
                           "exit": None, "watchdog": False, "parts": 0})

    def run(self):
        while not self.stopping:
            with self.lock:
                rc = self.life["proc"].proc.poll()
                if rc is not None and not self.stopping:
                    self.life["exit"] = rc
                    self.life["proc"].log.close()
            if rc is None:
                self.check_watchdog()
                time.sleep(0.1)
                continue
            if self.stopping:
                break
            time.sleep(RESTART_S)
            with self.lock:
                if not self.stopping:
                    self.start_daemon()

    def check_watchdog(self):
        life = self.life
        msgs = self.notify.messages[life["notify_from"]:]
        pings = [t for t, kv in msgs if kv in ("READY=1", "WATCHDOG=1")]
        if pings and time.monotonic() - pings[-1] > WATCHDOG_S and not life["watchdog"]:
            life["watchdog"] = True
            os.kill(life["pid"], signal.SIGABRT)

    def kill9(self):
        with self.lock:
            self.life["planned"] = "SIGKILL"
            os.kill(self.life["pid"], signal.SIGKILL)
            return self.life["gen"]

    def wait_up(self, after_gen, timeout=RECONNECT_TIMEOUT_S):
        """Until a daemon newer than after_gen says it is up."""
        rx = re.compile(r"hotgauged .* up: PLC on port")

        def up():
            life = self.life
            return life["gen"] > after_gen and life["exit"] is None and \
                rx.search(life["proc"].text())
        vl.wait_for(up, "the restarted hotgauged", timeout)

    def wait_first_up(self):
        self.life["proc"].wait_line(r"hotgauged .* up: PLC on port", 120)

    def log_count(self, pattern):
        return len(re.findall(pattern, self.life["proc"].text(), re.M))

    def idle_rss_kb(self, last):
        """RSS once the daemon is done with the last part (`last`: its part id and daemon
        generation): the part's log line comes after its archive is written, and its memory is
        given back right after. Sampled at once after DONE, it caught archives being written."""
        if last and last[1] == self.life["gen"]:
            rx = re.compile(r"\] part %s seq \d+ " % re.escape(str(last[0])))
            try:
                vl.wait_for(lambda: rx.search(self.life["proc"].text()), "the part's log line", 20)
                time.sleep(0.2)
            except Exception:  # noqa: BLE001 - a daemon that died meanwhile: sampled as it is
                pass
        return self.rss_kb()

    def rss_kb(self):
        try:
            with open(f"/proc/{self.life['pid']}/status") as f:
                return int(re.search(r"VmRSS:\s+(\d+)", f.read()).group(1))
        except (OSError, AttributeError):
            return None

    def stop(self):
        with self.lock:
            self.stopping = True
            life = self.life
            if life["exit"] is None:
                life["planned"] = "SIGTERM"
                try:
                    life["exit"] = life["proc"].stop(timeout=60)
                except RuntimeError as e:  # did not stop: killed by Process.stop
                    life["exit"] = f"hung at SIGTERM ({e})"
        self.thread.join(timeout=10)
        self.notify.stop = True


class Plc(vl.Plc):
    """The line PLC, which reconnects (every 0.5 s) whenever a request fails; `drops` counts
    the broken connections it saw."""

    def __init__(self, port):
        self.host, self.port = "127.0.0.1", port
        self.client, self.drops = None, 0

    def call(self, request, what, timeout=RECONNECT_TIMEOUT_S):
        deadline = time.monotonic() + timeout
        while True:
            try:
                if self.client is None:
                    self.client = ModbusTcpClient(self.host, port=self.port, timeout=3)
                    if not self.client.connect():
                        raise ConnectionError("connection refused")
                rr = request(self.client)
                if not rr.isError():
                    return rr
                err = rr
            except Exception as e:  # pymodbus raises several kinds when the peer is gone
                err = e
            self.close()
            self.drops += 1
            if time.monotonic() > deadline:
                raise RuntimeError(f"PLC: {what}: {err}")
            time.sleep(0.5)

    def close(self):
        if self.client is not None:
            self.client.close()
            self.client = None

    def inputs(self):
        return self.call(lambda c: c.read_input_registers(0, vl.N_INPUTS, slave=vl.UNIT),
                         "read").registers

    def write(self, address, values):
        self.call(lambda c: c.write_registers(address, values, slave=vl.UNIT), f"write {address}")

    def to_idle(self):
        """Acknowledges a result, or resets a fault or a cycle that timed out."""
        st = self.state()
        if st != vl.IDLE:
            self.write(0, [vl.ACK if st == vl.DONE else vl.RESET])
            self.wait_state({vl.IDLE}, 10)


# ---------------------------------------------------------------- the schedule

def schedule(parts, seed, every, first):
    """{part: [fault, ...]}: from part `first`, every `every` parts the next kind of a seeded
    round; a run kind covers its RUN_LENGTH parts (sighup: sighup_bad, then sighup_good)."""
    rng, order, plan, part = random.Random(seed), [], {}, first
    while part <= parts:
        if not order:
            order = list(KINDS)
            rng.shuffle(order)
        kind = order.pop(0)
        length = RUN_LENGTH.get(kind, 1)
        for k in range(min(length, parts - part + 1)):
            label = ("sighup_bad", "sighup_good")[k] if kind == "sighup" else kind
            plan.setdefault(part + k, []).append(label)
        part += max(every, length + 1)
    return plan


def part_id(first, n, attempt):
    return first + 10 * n + attempt


# ---------------------------------------------------------------- one part

class Soak:
    def __init__(self, a, line, relay, sup, plan):
        self.a, self.line, self.relay, self.sup, self.plan = a, line, relay, sup, plan
        self.plc = Plc(line.plc_port)
        self.conveyor = vl.Conveyor(line.axis_port)
        self.good_config = open(line.config_path).read()
        self.reloads = 0
        self.last_done = None  # (part id, daemon generation) of the last trigger answered

    def run_part(self, n):
        faults = list(self.plan.get(n, []))
        rec = {"part": n, "faults": faults, "attempts": [], "notes": [], "t0": time.time()}
        t0 = time.monotonic()
        wall_minus_mono = rec["t0"] - t0
        self.conditions(faults, rec)
        self.before(faults, rec)
        self.conveyor.load(n, timeout=120)
        on_busy = self.disconnect if "plc_disconnect" in faults else \
            self.kill_busy if "kill_busy" in faults else None
        att = self.attempt(n, 1, on_busy)
        rec["attempts"].append(att)
        if att["state"] == "LOST":
            self.after_restart(rec, att["gen"])
            rec["attempts"].append(self.attempt(n, 2, None))
        self.after(faults, rec)
        rec["wall_s"] = time.monotonic() - t0
        # The wall clock stepped during the part (a VM paused and resumed, NTP): timestamps on
        # it (camera, accelerometer, the virtual cell's pacing) jumped under the daemon.
        rec["clock_step_s"] = round(time.time() - time.monotonic() - wall_minus_mono, 3)
        rec["gen"], rec["rss_kb"] = self.sup.life["gen"], self.sup.rss_kb()
        rec["rss_idle_kb"] = rec["attempts"][-1]["rss_idle_kb"]
        self.sup.life["parts"] += 1
        return rec

    def conditions(self, faults, rec):
        """The accelerometer relay's loss and the camera link's packet loss for this part."""
        self.relay.loss = max([ACCEL_LOSS[f] for f in faults if f in ACCEL_LOSS], default=0.0)
        self.relay.on = "accel_outage" not in faults
        want = PACKET_LOSS if "cam_packet_loss" in faults else 0.0
        if want != self.line.packet_loss:
            self.restart_cell(want, rec)
            if "cam_restart" not in faults:
                faults.append("cam_restart")

    def restart_cell(self, packet_loss, rec):
        self.conveyor.close()
        self.line.restart_cell(packet_loss)
        self.conveyor = vl.Conveyor(self.line.axis_port)
        rec["notes"].append(f"camera restarted (packet loss {packet_loss})")

    def before(self, faults, rec):
        if "cam_restart" in faults and not any("camera restarted" in x for x in rec["notes"]):
            self.restart_cell(None, rec)
        if "sighup_bad" in faults:
            self.sighup(self.good_config.replace("camera:", "camera: [unclosed\n  id:", 1),
                        r"reload REJECTED", rec)
        if "sighup_good" in faults:
            self.reloads += 1
            self.sighup(self.good_config + f"# soak reload {self.reloads}\n",
                        r"reloaded: config hash", rec)
        if "kill_idle" in faults:
            self.after_restart(rec, self.sup.kill9())
        if "disk_full" in faults:
            self.fsize(max((os.path.getsize(os.path.join(self.line.results_dir, f))
                            for f in os.listdir(self.line.results_dir)), default=0))

    def after(self, faults, rec):
        if "disk_full" in faults:
            self.fsize("unlimited")
        if "accel_outage" in faults:
            self.relay.on = True
            time.sleep(1.0)  # the accelerometer ring fills again before the next part

    def sighup(self, text, pattern, rec):
        with open(self.line.config_path, "w") as f:
            f.write(text)
        before = self.sup.log_count(pattern)
        os.kill(self.sup.life["pid"], signal.SIGHUP)
        try:
            vl.wait_for(lambda: self.sup.log_count(pattern) > before, pattern, 20)
            rec["notes"].append(f"log: {pattern}")
        except TimeoutError:
            rec["notes"].append(f"NO '{pattern}' in the log within 20 s")
        if "REJECTED" in pattern:  # the bad file must never meet a restart: put the good back
            with open(self.line.config_path, "w") as f:
                f.write(self.good_config)

    def fsize(self, limit):
        subprocess.run(["prlimit", "--pid", str(self.sup.life["pid"]), f"--fsize={limit}:unlimited"
                        if limit != "unlimited" else "--fsize=unlimited"], check=True)

    def after_restart(self, rec, killed_gen):
        """After a kill: wait for the restarted daemon; input 5 against the files."""
        self.sup.wait_up(killed_gen)
        r = self.plc.inputs()
        last = last_sequence(self.line.results_dir)
        rec["restart"] = {"state": r[1], "input5": r[5], "files_last_sequence": last}

    def disconnect(self, att):
        time.sleep(1.0)
        self.plc.close()
        time.sleep(3.0)
        att["notes"] = "PLC disconnected 1 s into BUSY for 3 s"

    def kill_busy(self, att):
        delay = random.Random(self.a.seed * 100003 + att["part"]).uniform(0.3, 7.0)
        time.sleep(delay)
        att["killed_gen"] = self.sup.kill9()
        att["notes"] = f"kill -9 {delay:.1f} s into BUSY"

    def attempt(self, n, k, on_busy):
        """One trigger: until DONE, FAULT, or IDLE after a broken connection (a restart took the
        cycle: LOST)."""
        pid = part_id(self.a.first_part_id, n, k)
        att = {"part": n, "attempt": k, "part_id": pid, "gen": self.sup.life["gen"]}
        self.plc.to_idle()
        att["rss_idle_kb"] = self.sup.idle_rss_kb(self.last_done)  # the last part done with
        drops = self.plc.drops
        t0 = time.monotonic()
        self.plc.trigger(pid)
        r = self.plc.inputs()
        att["command_status"] = r[3]
        while r[1] not in (vl.DONE, vl.FAULT):
            if r[1] == vl.BUSY and on_busy:
                on_busy(att)
                on_busy = None
            elif r[1] == vl.IDLE and self.plc.drops > drops:
                att.update(state="LOST", cycle_s=time.monotonic() - t0)
                return att
            if time.monotonic() - t0 > CYCLE_TIMEOUT_S:
                att.update(state="TIMEOUT", cycle_s=time.monotonic() - t0)
                return att
            time.sleep(0.05)
            r = self.plc.inputs()
        att["cycle_s"] = time.monotonic() - t0
        self.last_done = (pid, att["gen"])
        d = vl.decode(r)
        att.update(state="DONE" if d["state"] == vl.DONE else "FAULT", error=d["error"],
                   sequence=d["sequence"], echo_id=d["part_id"], verdict=d["verdict"],
                   temperature_c=d["temperature_c"],
                   features={str(s): f for s, f in d["features"].items()})
        self.plc.to_idle()
        return att


# ---------------------------------------------------------------- the files

def read_jsonl(results_dir):
    out = []
    for name in sorted(os.listdir(results_dir)):
        if name.endswith(".jsonl"):
            with open(os.path.join(results_dir, name)) as f:
                out += [json.loads(t) for t in f if t.strip()]
    return out


def read_csv_rows(results_dir):
    names = sorted(f for f in os.listdir(results_dir)
                   if f.endswith(".csv") and ".verification" not in f)
    return vl.read_csvs(results_dir, names)


def last_sequence(results_dir):
    lines = read_jsonl(results_dir)
    return lines[-1]["sequence"] if lines else None


def tolerances():
    recipe = vl.yaml.safe_load(open(os.path.join(vl.REPO, "config/parts/hub-a.yaml")))
    return {str(f["slot"]): (f["name"], f["nominal_mm"] + f["tolerance_mm"][0],
                             f["nominal_mm"] + f["tolerance_mm"][1]) for f in recipe["features"]}


def add_truth_errors(line, rec, tol):
    """Per feature of each DONE attempt: the truth, the error, whether the truth is in
    tolerance."""
    truth = line.truth(rec["part"])
    for att in rec["attempts"]:
        for slot, f in att.get("features", {}).items():
            name, lo, hi = tol[slot]
            f["name"], f["truth_mm"] = name, truth[name]
            f["truth_in_tol"] = lo <= truth[name] <= hi
            f["error_mm"] = None if f["um"] is None else f["mm"] - truth[name]


# ---------------------------------------------------------------- checks

class Checks:
    """Collects failures by check name."""

    def __init__(self):
        self.failures = collections.defaultdict(list)

    def fail(self, check, text):
        self.failures[check].append(text)

    def ok(self):
        return not self.failures


def attempts(records):
    return [a for r in records for a in r["attempts"]]


def check_accounting(records, lines, rows, ck):
    """Lost, duplicated, and each PLC answer against its row. Returns figures."""
    by_id = collections.defaultdict(list)
    for j in lines:
        by_id[j["part"]["part_id"]].append(j)
    seqs = collections.Counter(j["sequence"] for j in lines)
    csv_seqs = collections.Counter(int(r["sequence"]) for r in rows)
    dup_seq = sorted(s for s, c in seqs.items() if c > 1)
    dup_csv = sorted(s for s, c in csv_seqs.items() if c > 1)
    dup_id = sorted(i for i, js in by_id.items() if len(js) > 1)
    plc_seqs = collections.Counter(a["sequence"] for a in attempts(records) if a["state"] == "DONE")
    dup_plc = sorted(s for s, c in plc_seqs.items() if c > 1)
    for what, dups in (("sequence in the JSON lines", dup_seq), ("sequence in the CSV", dup_csv),
                       ("part id in the files", dup_id), ("PLC input 5 over DONEs", dup_plc)):
        for d in dups:
            ck.fail("duplicated", f"{what}: {d} more than once")
    unpaired = sorted(set(seqs) ^ set(csv_seqs))
    for s in unpaired:
        ck.fail("duplicated", f"sequence {s}: a JSON line without its CSV row or the reverse")
    triggered = {str(a["part_id"]) for a in attempts(records)}
    for i in sorted(set(by_id) - triggered):
        ck.fail("lost", f"a row for part id {i}, which the PLC never triggered")
    lost = 0
    for rec in records:
        for a in rec["attempts"]:
            lost += not check_attempt_row(rec, a, by_id.get(str(a["part_id"]), []), ck)
    gaps = sorted(set(range(min(seqs), max(seqs) + 1)) - set(seqs)) if seqs else []
    taken = sum(1 for a in attempts(records) if a.get("error") == 206 or "killed_gen" in a)
    if len(gaps) > taken:
        ck.fail("lost", f"sequence numbers missing from the files: {gaps}; only {taken} cycles "
                "(FAULT 206, killed) may leave one out")
    return {"rows_json": len(lines), "rows_csv": len(rows), "lost": lost, "sequence_gaps": gaps,
            "duplicated": len(dup_seq) + len(dup_csv) + len(dup_id) + len(dup_plc) + len(unpaired),
            "sequence_first_last": [min(seqs), max(seqs)] if seqs else None}


def check_reuse(workdir, ck):
    """No sequence number given to two parts: every number a daemon gave (its log's "part ID seq N
    recipe" lines, results stored or not: FAULT 206 too) names one part id. Returns the count of
    numbers given, the reused ones."""
    given = collections.defaultdict(set)
    for name in sorted(os.listdir(workdir)):
        if re.fullmatch(r"hotgauged\.\d+\.log", name):
            with open(os.path.join(workdir, name), errors="replace") as f:
                for m in re.finditer(r"part (\S+) seq (\d+) recipe", f.read()):
                    given[int(m.group(2))].add(m.group(1))
    reused = sorted(s for s, ids in given.items() if len(ids) > 1)
    for s in reused:
        ck.fail("reused", f"sequence {s} given to parts {sorted(given[s])}")
    return {"sequences_given": len(given), "reused": len(reused)}


def check_attempt_row(rec, a, js, ck):
    """One trigger against the rows with its part id; False when it counts as lost."""
    where = f"part {rec['part']} attempt {a['attempt']} (id {a['part_id']}, {a['state']})"
    if a["state"] == "DONE":
        if len(js) != 1:
            ck.fail("lost", f"{where}: DONE at the PLC, {len(js)} rows in the files")
            return False
        compare_done(where, a, js[0], ck)
    elif a["state"] == "FAULT" and a["error"] == 206:
        if js:
            ck.fail("flagged", f"{where}: FAULT 206 (not stored) but the files have its row")
    elif a["state"] == "FAULT":
        if len(js) != 1 or js[0]["part"]["verdict"] != "NOT_MEASURED":
            verdicts = [j["part"]["verdict"] for j in js]
            ck.fail("lost", f"{where}: FAULT {a['error']}, rows {verdicts}")
            return False
    elif a["state"] == "LOST" and "killed_gen" in a:
        a["row_after_kill"] = [j["part"]["verdict"] for j in js]
        if len(js) > 1:
            ck.fail("duplicated", f"{where}: killed cycle with {len(js)} rows")
    else:
        ck.fail("lost", f"{where}: the trigger ended in neither DONE nor FAULT")
        return False
    return True


def compare_done(where, a, j, ck):
    """The PLC's DONE against its JSON line: sequence, part id, verdicts, values to 1 µm."""
    part = j["part"]
    if a["sequence"] != j["sequence"] & 0xFFFF:
        ck.fail("plc_vs_files", f"{where}: input 5 {a['sequence']}, row sequence {j['sequence']}")
    if a["echo_id"] != a["part_id"]:
        ck.fail("plc_vs_files", f"{where}: PLC echoes part id {a['echo_id']}")
    file_verdict = part["verdict"]
    if part["degraded"] and file_verdict == "OK":
        file_verdict = "DEGRADED"
    if a["verdict"] != file_verdict:
        ck.fail("plc_vs_files", f"{where}: PLC verdict {a['verdict']}, files {part['verdict']}"
                f" (degraded {part['degraded']})")
    for f in part["features"]:
        p = a["features"].get(str(f["slot"]))
        if p is None:
            ck.fail("plc_vs_files", f"{where}: {f['name']} not in the registers")
            continue
        um = None if f["cold_mm"] is None or p["verdict"] == "NOT_MEASURED" else \
            round(f["cold_mm"] * 1000)
        if (um is None) != (p["um"] is None) or (um is not None and abs(um - p["um"]) > 1):
            ck.fail("plc_vs_files", f"{where}: {f['name']} PLC {p['um']} µm, files {f['cold_mm']}")


def check_values(records, max_error, ck):
    """False NOK, and trusted values off the truth. Returns figures."""
    false_nok, noks, worst = [], 0, collections.defaultdict(float)
    for rec in records:
        kind = "+".join(sorted(rec["faults"])) or "clean"
        for a in rec["attempts"]:
            for f in a.get("features", {}).values():
                if f["verdict"] == "NOK":
                    noks += 1
                    if f["truth_in_tol"]:
                        false_nok.append(f"part {rec['part']}: {f['name']} NOK at {f['mm']:.4f}, "
                                         f"true {f['truth_mm']:.4f} (within tolerance)")
                if f["verdict"] in ("OK", "NOK") and f["error_mm"] is not None:
                    worst[kind] = max(worst[kind], abs(f["error_mm"]))
                    if abs(f["error_mm"]) > max_error:
                        ck.fail("wrong_value", f"part {rec['part']} [{kind}]: {f['name']} "
                                f"{f['verdict']} off the truth by {f['error_mm']:+.4f} mm")
    for text in false_nok:
        ck.fail("false_nok", text)
    return {"nok_features": noks, "false_nok": len(false_nok),
            "worst_trusted_error_mm": {k: round(v, 4) for k, v in sorted(worst.items())}}


def accel_reasons_only(reasons):
    return all("accelerometer" in r for r in reasons)


def judge(rec, lines_by_id):
    """Whether each fault on the part was flagged right; a list of problems."""
    faults, atts, out = set(rec["faults"]), rec["attempts"], []
    final = atts[-1]
    row = (lines_by_id.get(str(final["part_id"])) or [None])[0]
    reasons = row["part"]["degraded_reasons"] if row else []
    flagged = final.get("verdict") in ("DEGRADED", "NOT_MEASURED") or \
        bool(row and row["part"]["degraded"])
    if "disk_full" in faults:
        if (final["state"], final.get("error")) != ("FAULT", 206):
            out.append(f"disk full: {final['state']} {final.get('error')}, not FAULT 206")
        return out
    if final["state"] != "DONE":
        return out + [f"{final['state']} {final.get('error')}, not DONE"]
    if "kill_busy" in faults:
        first = atts[0]
        if first["state"] != "LOST" or len(atts) != 2:
            out.append(f"kill in BUSY: first attempt {first['state']}, not taken by the restart")
        else:
            out += killed_row_problems(rec, lines_by_id.get(str(first["part_id"]), []))
    if "restart" in rec:
        rs = rec["restart"]
        if rs["files_last_sequence"] is not None and \
                rs["input5"] != rs["files_last_sequence"] & 0xFFFF:
            out.append(f"after restart input 5 = {rs['input5']}, files' last sequence "
                       f"{rs['files_last_sequence']}")
    for note in rec["notes"]:
        if note.startswith("NO "):
            out.append(note)
    if "accel_outage" in faults:
        if not (row and row["part"]["degraded"] and any("accelerometer" in r for r in reasons)):
            out.append(f"accelerometer outage not flagged: {final['verdict']}, "
                       f"reasons {reasons[:2]}")
        if final["verdict"] == "OK":
            out.append("accelerometer outage: plain OK")
    elif faults & set(ACCEL_LOSS):
        if flagged and not accel_reasons_only(reasons):
            out.append(f"accelerometer loss flagged with other reasons: {reasons[:2]}")
    elif flagged:
        out.append(f"{final['verdict']} without an accelerometer fault: degraded {reasons[:2]}, "
                   f"not measured {not_measured(row)}")
    return out


def not_measured(row):
    """The not measured features of a row, with their reasons."""
    return [f"{f['name']}: {f['reason']}" for f in (row["part"]["features"] if row else [])
            if f["verdict"] == "NOT_MEASURED"][:3]


def killed_row_problems(rec, js):
    """A killed cycle's row: none, NOT_MEASURED, or (written before the kill, never shown) a
    whole result whose trusted values agree with the truth."""
    truth = {f["name"]: f["truth_mm"] for f in rec["attempts"][-1].get("features", {}).values()}
    out = []
    for j in js:
        if j["part"]["verdict"] == "NOT_MEASURED":
            continue
        rec["notes"].append(f"killed cycle has a whole row: {j['part']['verdict']}, "
                            f"sequence {j['sequence']}")
        for f in j["part"]["features"]:
            if f["verdict"] in ("OK", "NOK") and f["name"] in truth and \
                    abs(f["cold_mm"] - truth[f["name"]]) > 0.1:
                out.append(f"killed cycle's row: {f['name']} {f['cold_mm']} vs true "
                           f"{truth[f['name']]}")
    return out


def check_faults(records, lines, ck):
    by_id = collections.defaultdict(list)
    for j in lines:
        by_id[j["part"]["part_id"]].append(j)
    per_kind = collections.defaultdict(lambda: [0, 0])
    for rec in records:
        problems = judge(rec, by_id)
        if problems and abs(rec.get("clock_step_s", 0)) > CLOCK_STEP_S:
            # Not the daemon's doing: listed in the report, not failed (a false NOK still is).
            rec["environment"] = [f"wall clock stepped {rec['clock_step_s']} s"] + problems
            problems = []
        rec["problems"] = problems
        for k in rec["faults"] or ["clean"]:
            per_kind[k][0] += 1
            per_kind[k][1] += not problems
        for p in problems:
            ck.fail("flagged", f"part {rec['part']} [{', '.join(rec['faults']) or 'clean'}]: {p}")
    return {k: {"parts": v[0], "as_expected": v[1]} for k, v in sorted(per_kind.items())}


def check_exits(sup, ck):
    exits = []
    for life in sup.lives:
        planned = life["planned"]
        rc = life["exit"]
        exits.append({"gen": life["gen"], "pid": life["pid"], "exit": rc, "planned": planned,
                      "watchdog": life["watchdog"], "parts": life["parts"]})
        expected = (planned == "SIGKILL" and rc == -signal.SIGKILL) or \
                   (planned == "SIGTERM" and rc == 0)
        if not expected:
            ck.fail("crashes", f"hotgauged.{life['gen']} (pid {life['pid']}) exit {rc}"
                    f"{' after the watchdog' if life['watchdog'] else ''}; planned {planned}; "
                    f"log hotgauged.{life['gen']}.log")
    return exits


def check_rss(records, ck):
    """RSS of the idle daemon before each part's trigger (right after a part it swings with
    the buffers of the archive and pipeline); flat: median of the last 100 parts within 10 % of
    parts 100-200."""
    lives = collections.OrderedDict()
    for r in records:
        if r["rss_idle_kb"]:
            lives.setdefault(r["attempts"][-1]["gen"], []).append(r["rss_idle_kb"])
    per_life = [{"gen": g, "parts": len(v), "first_kb": v[0], "last_kb": v[-1], "max_kb": max(v)}
                for g, v in lives.items()]
    out = {"per_lifetime": per_life}
    rss = {r["part"]: r["rss_idle_kb"] for r in records if r["rss_idle_kb"]}
    if len(records) >= 300:
        mid = statistics.median(v for p, v in rss.items() if 100 <= p <= 200)
        last = statistics.median(v for p, v in rss.items() if p > len(records) - 100)
        out.update(median_parts_100_200_kb=mid, median_last_100_kb=last,
                   change=round(last / mid - 1, 4))
        if abs(last / mid - 1) > 0.10:
            ck.fail("rss", f"RSS median {last} kB over the last 100 parts, {mid} kB over 100-200")
    else:
        out["flatness"] = "not checked (fewer than 300 parts)"
    return out


def cycle_figures(records):
    done = [a["cycle_s"] for a in attempts(records) if a["state"] == "DONE"]
    clean = [a["cycle_s"] for r in records if not r["faults"] for a in r["attempts"]
             if a["state"] == "DONE"]
    walls = [r["wall_s"] for r in records]
    f = lambda v: {"n": len(v), "median_s": round(statistics.median(v), 2),  # noqa: E731
                   "max_s": round(max(v), 2)} if v else None
    return {"done_all": f(done), "done_clean": f(clean), "wall_per_part": f(walls),
            "wall_mean_s": round(statistics.mean(walls), 2) if walls else None,
            "projected_1000_parts_h": round(statistics.mean(walls) * 1000 / 3600, 2)
            if walls else None}


def tallies(records, lines):
    codes, verdicts, causes = (collections.Counter() for _ in range(3))
    for a in attempts(records):
        if a["state"] == "FAULT":
            codes[str(a["error"])] += 1
        elif a["state"] == "DONE":
            verdicts[a["verdict"]] += 1
        else:
            codes[a["state"] + (" (injected kill)" if "killed_gen" in a else "")] += 1
    for j in lines:
        for r in j["part"]["degraded_reasons"]:
            causes[cause_of(r)] += 1
    return {"faults_by_code": dict(codes), "verdicts": dict(verdicts),
            "degraded_causes": dict(causes)}


def cause_of(reason):
    for c in ("non-finite accelerometer samples", "clipped accelerometer samples",
              "accelerometer gap", "accelerometer record does not cover", "accelerometer"):
        if c in reason:
            return c
    return reason[:60]


# ---------------------------------------------------------------- report

def print_report(rep):
    f = rep["figures"]
    print("\n==== soak report ====")
    print(f"parts in: {rep['parts']} ({f['triggers']} triggers); results out: "
          f"{f['rows_json']} JSON lines, {f['rows_csv']} CSV rows (sequence "
          f"{f['sequence_first_last']}); lost {f['lost']}; duplicated {f['duplicated']}; "
          f"reused {f['reused']} (of {f['sequences_given']} numbers given); "
          f"false NOK {f['false_nok']} (of {f['nok_features']} NOK features)")
    print(f"sequence numbers not in the files: {f['sequence_gaps']}")
    print("after each restart, before a DONE: " + "; ".join(
        f"part {r['part']}: state {r['state']}, input 5 = {r['input5']}, files' last sequence "
        f"{r['files_last_sequence']}" for r in f["restarts"]))
    print(f"verdicts at the PLC: {f['verdicts']}")
    print(f"faults by code: {f['faults_by_code']}")
    print(f"degraded causes (features): {f['degraded_causes']}")
    print("faults injected -> parts handled as expected:")
    for k, v in f["by_fault"].items():
        print(f"  {k:<16} {v['as_expected']:4d} / {v['parts']}")
    print(f"worst |error| of trusted features vs truth, mm: {f['worst_trusted_error_mm']}")
    print(f"environment events (not failed; the machine, not the daemon): "
          f"{f.get('environment') or 'none'}")
    print("daemon lifetimes:")
    for e in rep["exits"]:
        print(f"  hotgauged.{e['gen']}: pid {e['pid']}, {e['parts']} parts, exit {e['exit']} "
              f"(planned {e['planned']})")
    print("RSS of the idle daemon before each trigger, per lifetime (kB):")
    for life in f["rss"]["per_lifetime"]:
        print(f"  hotgauged.{life['gen']}: {life['parts']} parts, first {life['first_kb']}, "
              f"last {life['last_kb']}, max {life['max_kb']}")
    print(f"RSS flatness: {({k: v for k, v in f['rss'].items() if k != 'per_lifetime'})}")
    print(f"cycle time (trigger to DONE): all {f['cycle']['done_all']}, clean parts "
          f"{f['cycle']['done_clean']}; wall time per part {f['cycle']['wall_per_part']}, mean "
          f"{f['cycle']['wall_mean_s']} s: 1000 parts ~ {f['cycle']['projected_1000_parts_h']} h")
    print(f"accelerometer relay: {f['relay']}")
    if rep["failures"]:
        print("FAILED checks:")
        for check, items in rep["failures"].items():
            print(f"  {check}: {len(items)}")
            for t in items[:20]:
                print(f"    - {t}")
    print("soak: " + ("all checks passed" if not rep["failures"] else "FAILED"))


def write_outputs(out, records, rep):
    with open(os.path.join(out, "parts.jsonl"), "w") as f:
        for r in records:
            f.write(json.dumps(r) + "\n")
    with open(os.path.join(out, "rss.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["part", "time", "daemon", "rss_idle_before_kb", "rss_after_kb"])
        for r in records:
            w.writerow([r["part"], round(r["t0"] + r["wall_s"], 1), r["gen"], r["rss_idle_kb"],
                        r["rss_kb"]])
    with open(os.path.join(out, "report.json"), "w") as f:
        json.dump(rep, f, indent=1)


def part_line(rec):
    a = rec["attempts"][-1]
    what = a["state"] if a["state"] != "DONE" else f"{a['verdict']}"
    if a["state"] == "FAULT":
        what = f"FAULT {a['error']}"
    first = rec["attempts"][0]
    pre = f"{first['state']} ({first.get('notes', '')}), then " if len(rec["attempts"]) > 1 else ""
    return (f"part {rec['part']:4d} [{', '.join(rec['faults']) or 'clean'}]: {pre}{what}, "
            f"seq {a.get('sequence')}, cycle {a.get('cycle_s', 0):.1f} s, "
            f"wall {rec['wall_s']:.1f} s,"
            f" hotgauged.{rec['gen']} RSS {rec['rss_idle_kb']}/{rec['rss_kb']} kB (idle/after)")


# ---------------------------------------------------------------- main

def evaluate(a, line, sup, relay, records):
    lines, rows = read_jsonl(line.results_dir), read_csv_rows(line.results_dir)
    ck = Checks()
    fig = check_accounting(records, lines, rows, ck)
    fig.update(check_reuse(line.workdir, ck))
    fig.update(check_values(records, a.max_error_mm, ck))
    fig["by_fault"] = check_faults(records, lines, ck)
    fig["environment"] = [{"part": r["part"], "events": r["environment"]} for r in records
                          if r.get("environment")]
    exits = check_exits(sup, ck)
    fig["rss"] = check_rss(records, ck)
    fig["cycle"] = cycle_figures(records)
    fig.update(tallies(records, lines))
    fig["triggers"] = len(attempts(records))
    fig["restarts"] = [{"part": r["part"], **r["restart"]} for r in records if "restart" in r]
    fig["relay"] = {"passed": relay.passed, "dropped": relay.dropped}
    return {"parts": len(records), "seed": a.seed, "figures": fig, "exits": exits,
            "failures": dict(ck.failures), "workdir": line.workdir}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bin-dir", default=os.path.join(vl.REPO, "build"))
    ap.add_argument("--parts", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", help="working folder (kept); default: a temporary one")
    ap.add_argument("--address", default="127.0.0.9", help="the virtual camera's address")
    ap.add_argument("--first-part-id", type=int, default=3000000)
    ap.add_argument("--every", type=int, default=4, help="parts from one fault to the next")
    ap.add_argument("--first-fault", type=int, default=3)
    ap.add_argument("--max-error-mm", type=float, default=0.1,
                    help="a trusted (OK/NOK) feature further than this from the truth fails")
    ap.add_argument("--lines", type=int, default=1,
                    help="independent lines run at once, the parts shared out (a line uses about "
                         "a third of a core)")
    a = ap.parse_args()
    a.bin_dir = os.path.abspath(a.bin_dir)
    if a.lines > 1:
        return run_lines(a)
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    if a.out:
        shutil.rmtree(a.out, ignore_errors=True)
        os.makedirs(a.out)
    workdir = os.path.abspath(a.out) if a.out else tempfile.mkdtemp(prefix="hotgauge-soak-")
    plan = schedule(a.parts, a.seed, a.every, a.first_fault)
    print(f"soak: {a.parts} parts, seed {a.seed}, work folder {workdir}\nschedule: " +
          ", ".join(f"{p}: {'+'.join(f)}" for p, f in sorted(plan.items())), flush=True)
    line = SoakLine(a.bin_dir, workdir, a.address, seed=a.seed)
    relay = sup = None
    records, rep = [], None
    try:
        line.start_pty()
        relay = LossyRelay(line.accel_port, a.seed)
        line.start_cell(accel_to=f"127.0.0.1:{relay.port}")
        line.write_config()
        sup = Supervisor(line)
        sup.wait_first_up()
        soak = Soak(a, line, relay, sup, plan)
        tol = tolerances()
        for n in range(1, a.parts + 1):
            rec = soak.run_part(n)
            add_truth_errors(line, rec, tol)
            records.append(rec)
            print(part_line(rec), flush=True)
        soak.plc.close()
        soak.conveyor.close()
    except Exception as e:  # the report still covers the parts run so far
        print(f"soak ABORTED at part {len(records) + 1}: {type(e).__name__}: {e}", flush=True)
        records.append(None)
    finally:
        if sup:
            sup.stop()
        if relay:
            relay.stop = True
        line.stop()
    aborted = records and records[-1] is None
    records = [r for r in records if r]
    rep = evaluate(a, line, sup, relay, records) if sup and records else \
        {"failures": {"aborted": ["no part ran"]}, "figures": {}}
    if aborted:
        rep["failures"]["aborted"] = [f"the soak stopped after {len(records)} parts"]
    if rep["figures"]:
        write_outputs(workdir, records, rep)
        print_report(rep)
    ok = not rep["failures"]
    if not ok:
        print_tails(workdir, sup)
    elif not a.out:
        shutil.rmtree(workdir, ignore_errors=True)
    return 0 if ok else 1


def run_lines(a):
    """--lines K: K soak.py processes, each its own line (camera address, ports, seed, part ids,
    folder OUT/lineK), the parts shared out; then one summary over their report.json files."""
    out = os.path.abspath(a.out or tempfile.mkdtemp(prefix="hotgauge-soak-"))
    os.makedirs(out, exist_ok=True)
    children = []
    for i in range(a.lines):
        parts = a.parts // a.lines + (1 if i < a.parts % a.lines else 0)
        folder = os.path.join(out, f"line{i + 1}")
        address = ".".join(a.address.split(".")[:3] + [str(int(a.address.split(".")[3]) + i)])
        # Every option as given, but for what makes this line its own.
        own = dict(vars(a), lines=1, parts=parts, seed=a.seed + i, out=folder, address=address,
                   first_part_id=a.first_part_id + i * 1_000_000)
        cmd = [sys.executable, os.path.abspath(__file__)] + [
            x for k, v in own.items() for x in (f"--{k.replace('_', '-')}", str(v))]
        os.makedirs(folder, exist_ok=True)
        log = open(os.path.join(out, f"line{i + 1}.log"), "w")
        children.append((folder, log, subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)))
        print(f"line {i + 1}: {parts} parts, seed {a.seed + i}, camera {address}, log "
              f"{log.name}", flush=True)
    summary = {"lines": [], "failures": {}}
    for folder, log, proc in children:
        rc = proc.wait()
        log.close()
        path = os.path.join(folder, "report.json")
        rep = json.load(open(path)) if os.path.exists(path) else {"failures": {"aborted": [
            f"no report (exit {rc})"]}, "figures": {}}
        summary["lines"].append({"folder": folder, "exit": rc, "parts": rep.get("parts", 0),
                                 "figures": rep["figures"]})
        for check, items in rep["failures"].items():
            summary["failures"].setdefault(check, []).extend(f"{folder}: {t}" for t in items)
        if rc != 0 and not rep["failures"]:
            summary["failures"].setdefault("exit", []).append(f"{folder}: exit {rc}")
    print_lines_summary(summary)
    with open(os.path.join(out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=1)
    return 0 if not summary["failures"] else 1


def print_lines_summary(summary):
    lines = summary["lines"]
    total = lambda key: sum(x["figures"].get(key, 0) or 0 for x in lines)  # noqa: E731
    print("\n==== soak over all lines ====")
    for x in lines:
        f = x["figures"]
        print(f"{x['folder']}: exit {x['exit']}, {x['parts']} parts, lost {f.get('lost')}, "
              f"duplicated {f.get('duplicated')}, reused {f.get('reused')}, false NOK "
              f"{f.get('false_nok')}, worst trusted "
              f"error {f.get('worst_trusted_error_mm')} mm, RSS {f.get('rss', {}).get('change')}")
    worst = collections.defaultdict(float)  # by fault kind, over every line
    for x in lines:
        for kind, mm in (x["figures"].get("worst_trusted_error_mm") or {}).items():
            worst[kind] = max(worst[kind], mm)
    print(f"all lines: {sum(x['parts'] for x in lines)} parts, lost {total('lost')}, duplicated "
          f"{total('duplicated')}, reused {total('reused')}, false NOK {total('false_nok')}; "
          f"worst trusted error by fault "
          f"(mm): {dict(sorted(worst.items()))}")
    for check, items in summary["failures"].items():
        print(f"FAILED {check}: {len(items)}")
        for t in items[:20]:
            print(f"    - {t}")
    print("soak: " + ("all checks passed" if not summary["failures"] else "FAILED"))


def print_tails(workdir, sup, n=15):
    if sup:
        path = sup.life["proc"].log_path
        print(f"--- {os.path.basename(path)} (tail) ---\n" + "".join(open(path).readlines()[-n:]))
    print(f"work folder kept: {workdir}")


if __name__ == "__main__":
    sys.exit(main())
