#!/usr/bin/python3
"""Plant data end to end (docs/plant-data.md): the virtual line with a real Mosquitto broker on
loopback (TLS and password on), a subscriber (paho-mqtt) and the metrics endpoint scraped.

    /usr/bin/python3 plant_data_test.py BUILD [--outage-parts 30] [--out DIR]

1. A CA that did not sign the broker's certificate: hotgauged logs the failed handshake and tries
   again. A wrong password: hotgauged logs the broker's refusal and tries again with a growing delay,
   and measures a part all the same (its result waits in the spool). Restarted with the right
   password, that result is the first to reach the subscriber.
2. Full parts and one-face parts with the broker up: each result arrives.
3. The broker stopped for --outage-parts parts: every cycle takes as long as before, the PLC's
   device health shows the plant link (bit 5), the metrics show the spool growing by one a part.
4. The broker restarted: every spooled result arrives, in order; then more parts.
5. Checks: the subscriber got every results-file line exactly once, byte for byte, in the files'
   order; every payload valid against docs/schemas (jsonschema); the metrics, read by
   prometheus_client's parser, count what the results file holds; a late subscriber gets the
   retained state and health; hotgauged killed (SIGKILL) -> the broker's last will "offline".
"""
import argparse
import re
import glob
import json
import os
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request

import jsonschema
import paho.mqtt.client as mqtt
from prometheus_client.parser import text_string_to_metric_families

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from virtual_line import (DONE, REPO, Conveyor, Line, Plc, Process, free_port,  # noqa: E402
                          print_logs, run_part, wait_for)

CAMERA, BROKER = "127.0.0.25", "127.0.0.26"  # this test's own loopback addresses
SITE, CELL = "plant-7", "line-3"
USER, PASSWORD = "hotgauge-cell", "s3cret-for-the-test"
PLANT_LINK_BIT = 32  # PLC input 113, bit 5
TOPIC = f"hotgauge/{SITE}/{CELL}"


def openssl(*args, cwd):
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True)


def make_pki(d):
    """A CA and the broker's certificate for BROKER's IP address."""
    openssl("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", "ca.key", "-out",
            "ca.crt", "-days", "2", "-subj", "/CN=hotgauge test CA", cwd=d)
    openssl("req", "-newkey", "rsa:2048", "-nodes", "-keyout", "broker.key", "-out", "broker.csr",
            "-subj", f"/CN={BROKER}", cwd=d)
    with open(os.path.join(d, "san.ext"), "w") as f:
        f.write(f"subjectAltName=IP:{BROKER}\n")
    openssl("x509", "-req", "-in", "broker.csr", "-CA", "ca.crt", "-CAkey", "ca.key",
            "-CAcreateserial", "-out", "broker.crt", "-days", "2", "-extfile", "san.ext", cwd=d)


class Broker:
    """Mosquitto on BROKER:port, TLS only, no anonymous clients, sessions kept across restarts."""

    def __init__(self, workdir, port):
        self.workdir, self.port = workdir, port
        self.dir = os.path.join(workdir, "broker")
        os.makedirs(self.dir)
        make_pki(self.dir)
        passwd = os.path.join(self.dir, "passwd")
        subprocess.run(["mosquitto_passwd", "-c", "-b", passwd, USER, PASSWORD], check=True,
                       capture_output=True)
        self.conf = os.path.join(self.dir, "mosquitto.conf")
        with open(self.conf, "w") as f:
            f.write(("user root\n" if os.getuid() == 0 else "") +
                    f"per_listener_settings false\nallow_anonymous false\n"
                    f"password_file {passwd}\npersistence true\n"
                    f"persistence_location {self.dir}/\nlog_dest file {self.dir}/broker.log\n"
                    f"listener {port} {BROKER}\ncafile {self.dir}/ca.crt\n"
                    f"certfile {self.dir}/broker.crt\nkeyfile {self.dir}/broker.key\n")
        self.proc = None
        self.runs = 0

    def start(self):
        self.runs += 1
        self.proc = Process(f"mosquitto-{self.runs}", ["mosquitto", "-c", self.conf], self.workdir)
        wait_for(self.accepts, f"mosquitto accepting on {BROKER}:{self.port}", 10)
        return self

    def accepts(self):
        if self.proc.proc.poll() is not None:
            raise RuntimeError(f"mosquitto exited:\n{self.proc.text()}")
        try:
            socket.create_connection((BROKER, self.port), timeout=1).close()
            return True
        except OSError:
            return False

    def stop(self):
        if self.proc:
            assert self.proc.stop(10) == 0, "mosquitto did not stop cleanly"
            self.proc = None

    @property
    def ca(self):
        return os.path.join(self.dir, "ca.crt")


class Subscriber:
    """A plant historian's client: QoS 1, a session the broker keeps while it is away."""

    def __init__(self, broker, client_id, clean_session=False):
        self.messages = []  # (topic, payload text, retained), in arrival order
        self.lock = threading.Lock()
        self.client = mqtt.Client(client_id=client_id, clean_session=clean_session)
        self.client.tls_set(ca_certs=broker.ca)
        self.client.username_pw_set(USER, PASSWORD)
        self.client.reconnect_delay_set(min_delay=1, max_delay=2)
        self.client.on_connect = lambda c, u, f, rc: c.subscribe(f"{TOPIC}/#", qos=1)
        self.client.on_message = self.on_message
        self.client.connect(BROKER, broker.port, keepalive=10)
        self.client.loop_start()

    def on_message(self, client, userdata, msg):
        with self.lock:
            self.messages.append((msg.topic, msg.payload.decode(), bool(msg.retain)))

    def on(self, leaf):
        with self.lock:
            return [(p, r) for t, p, r in self.messages if t == f"{TOPIC}/{leaf}"]

    def results(self):
        return [p for p, _ in self.on("result")]

    def close(self):
        self.client.loop_stop()
        self.client.disconnect()


def mqtt_config(workdir, broker, password, ca=None):
    path = os.path.join(workdir, f"mqtt-password-{len(password)}")
    with open(path, "w") as f:
        f.write(password + "\n")
    return (f"mqtt:\n  host: {BROKER}\n  port: {broker.port}\n  site: {SITE}\n  cell: {CELL}\n"
            f"  username: {USER}\n  password_file: {path}\n  tls: {{ca_file: {ca or broker.ca}}}\n"
            f"  keepalive_s: 5\n  retry_min_s: 0.5\n  retry_max_s: 2\n"
            f"metrics: {{bind_address: 127.0.0.1, port: 0}}\n")


def scrape(line):
    urls = [l.split("metrics on ", 1)[1].strip() for l in line.daemon.text().splitlines()
            if "metrics on http" in l]
    assert urls, "hotgauged did not log its metrics endpoint"
    with urllib.request.urlopen(urls[-1], timeout=5) as r:
        assert r.headers["Content-Type"].startswith("text/plain; version=0.0.4"), r.headers
        text = r.read().decode()
    samples = {}
    for family in text_string_to_metric_families(text):  # the oracle's parser
        for s in family.samples:
            samples[(s.name, tuple(sorted(s.labels.items())))] = s.value
    return samples


def metric(samples, name, **labels):
    return samples.get((name, tuple(sorted(labels.items()))), 0.0)


def jsonl_lines(results_dir):
    lines = []
    for path in sorted(glob.glob(os.path.join(results_dir, "*.jsonl"))):
        with open(path) as f:
            lines += [l.rstrip("\n") for l in f if l.strip()]
    return lines


def schema(name):
    with open(os.path.join(REPO, "docs/schemas", name)) as f:
        return json.load(f)


def restart_daemon(line, config_extra):
    assert line.daemon.stop() == 0
    line.config_extra = config_extra
    line.write_config()
    line.start_daemon()


def wrong_ca_phase(line, broker, workdir):
    """The broker's certificate checked against a CA that did not sign it."""
    line.daemon.wait_line(r"MQTT broker .*certificate verify failed.*next try in", 20)
    line.daemon.wait_line(r"(?s)certificate verify failed.*certificate verify failed", 20)
    print("wrong CA: the TLS handshake refused ('certificate verify failed'), retried",
          flush=True)
    restart_daemon(line, mqtt_config(workdir, broker, "not-the-password"))


def wrong_password_phase(line, broker, workdir, plc, conveyor):
    """Returns the number of parts measured and the first daemon's log."""
    line.daemon.wait_line(r"MQTT .*(not authori[sz]ed|bad user ?name or password)", 20)
    p = run_part(plc, conveyor, 1, 260001)
    assert p["state"] == DONE, "no part measured while the broker refuses the cell"
    log = line.daemon.text()
    delays = [float(x) for x in re.findall(r"next try in ([0-9.]+) s", log)]
    assert len(delays) >= 2 and max(delays) > min(delays), f"no growing retry delay: {delays}"
    health = plc.inputs()[113]
    assert health & PLANT_LINK_BIT, f"device health {health:#x} without the plant link's bit"
    print(f"wrong password: refused, retried after {delays[:5]} s; part measured, "
          f"device health {health:#x}", flush=True)
    restart_daemon(line, mqtt_config(workdir, broker, PASSWORD))
    return 1, log


def outage_phase(line, broker, plc, conveyor, sub, first, n_parts, baseline_s):
    broker.stop()
    wait_for(lambda: plc.inputs()[113] & PLANT_LINK_BIT, "the plant link's health bit", 10)
    cycles = []
    for i in range(n_parts):
        p = run_part(plc, conveyor, first + i, 260100 + i, face=1)
        assert p["state"] == DONE, f"outage part {i}: {p}"
        cycles.append(p["cycle_s"])
        wait_for(lambda: metric(scrape(line), "hotgauge_mqtt_spool_depth") == i + 1,
                 f"spool depth {i + 1}", 10)
    s = scrape(line)
    assert metric(s, "hotgauge_mqtt_connected") == 0
    assert metric(s, "hotgauge_device_up", device="plant link") == 0
    worst = max(cycles)
    print(f"broker down for {n_parts} parts: cycles {min(cycles):.2f}..{worst:.2f} s "
          f"(median {statistics.median(cycles):.2f} s; with the broker up "
          f"{min(baseline_s):.2f}..{max(baseline_s):.2f} s), spool depth "
          f"{metric(s, 'hotgauge_mqtt_spool_depth'):.0f}", flush=True)
    assert worst < max(baseline_s) + 1.5, f"a cycle waited on the broker: {worst:.2f} s"
    before = len(sub.results())
    t0 = time.monotonic()
    broker.start()
    wait_for(lambda: len(sub.results()) >= before + n_parts, f"{n_parts} spooled results", 60)
    print(f"broker back: the {n_parts} spooled results arrived within "
          f"{time.monotonic() - t0:.1f} s", flush=True)
    wait_for(lambda: not plc.inputs()[113] & PLANT_LINK_BIT, "the plant link working", 10)


def check_delivery(sub, lines):
    got = sub.results()
    seqs = [json.loads(p)["sequence"] for p in got]
    dupes = len(seqs) - len(set(seqs))
    assert dupes == 0, f"{dupes} results received twice: {seqs}"
    assert got == lines, (f"received {len(got)} results, the files hold {len(lines)}; "
                          f"sequences received {seqs}, in the files "
                          f"{[json.loads(l)['sequence'] for l in lines]}")
    result_schema = schema("mqtt-result.schema.json")
    for p in got:
        jsonschema.validate(json.loads(p), result_schema)
    for leaf in ("state", "health"):
        for p, _ in sub.on(leaf):
            jsonschema.validate(json.loads(p), schema(f"mqtt-{leaf}.schema.json"))
    print(f"subscriber: {len(got)} results, each once, byte-identical to the results file and "
          f"in its order (sequences {seqs[0]}..{seqs[-1]}); payloads valid against "
          f"docs/schemas", flush=True)


def check_metrics(line, lines, first_seq):
    s = scrape(line)
    mine = [json.loads(l) for l in lines if json.loads(l)["sequence"] >= first_seq]
    verdicts = {}
    for j in mine:
        verdicts[j["part"]["verdict"]] = verdicts.get(j["part"]["verdict"], 0) + 1
    for v, n in verdicts.items():
        assert metric(s, "hotgauge_cycles_total", verdict=v) == n, \
            (v, n, metric(s, "hotgauge_cycles_total", verdict=v))
    counted = sum(v for (name, _), v in s.items() if name == "hotgauge_cycles_total")
    assert counted == len(mine), f"metrics count {counted} parts, the file {len(mine)}"
    assert metric(s, "hotgauge_cycle_seconds_count") == len(mine)
    assert metric(s, "hotgauge_mqtt_published_total") == len(lines)
    assert metric(s, "hotgauge_mqtt_spool_depth") == 0
    assert metric(s, "hotgauge_camera_scans_total") > 0
    assert metric(s, "hotgauge_accel_samples_total") > 0
    print(f"metrics: cycles by verdict {verdicts} as in the results file; "
          f"{metric(s, 'hotgauge_mqtt_published_total'):.0f} published; mean cycle "
          f"{metric(s, 'hotgauge_cycle_seconds_sum') / len(mine):.2f} s", flush=True)


def check_retained_and_will(line, broker):
    late = Subscriber(broker, "late-historian", clean_session=True)
    try:
        wait_for(lambda: late.on("state") and late.on("health"), "retained state and health", 10)
        (state, r1), (health, r2) = late.on("state")[-1], late.on("health")[-1]
        assert r1 and r2, "state and health are not retained"
        assert json.loads(state)["state"] in ("idle", "busy"), state
        assert json.loads(health)["faults"] == 0, health
        line.daemon.proc.send_signal(signal.SIGKILL)
        t0 = time.monotonic()
        wait_for(lambda: any(json.loads(p)["state"] == "offline" for p, _ in late.on("state")),
                 "the last will", 15)
        print(f"retained state and health for a late subscriber; hotgauged killed: the will "
              f"'offline' after {time.monotonic() - t0:.1f} s (its connection closed without a goodbye)", flush=True)
    finally:
        late.close()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("bin_dir")
    ap.add_argument("--outage-parts", type=int, default=30)
    ap.add_argument("--out", help="working folder (kept)")
    a = ap.parse_args()
    workdir = os.path.abspath(a.out) if a.out else tempfile.mkdtemp(prefix="hotgauge-plant-")
    if a.out:
        shutil.rmtree(workdir, ignore_errors=True)
        os.makedirs(workdir)
    broker = Broker(workdir, free_port())
    line = Line(a.bin_dir, workdir, CAMERA)
    other_ca = os.path.join(workdir, "other-ca")
    os.makedirs(other_ca)
    openssl("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", "ca.key", "-out",
            "ca.crt", "-days", "2", "-subj", "/CN=another CA", cwd=other_ca)
    line.config_extra = mqtt_config(workdir, broker, PASSWORD, os.path.join(other_ca, "ca.crt"))
    ok, sub = False, None
    try:
        broker.start()
        sub = Subscriber(broker, "historian")
        line.start()
        wrong_ca_phase(line, broker, workdir)
        plc, conveyor = Plc(line.plc_port), Conveyor(line.axis_port)
        n, _ = wrong_password_phase(line, broker, workdir, plc, conveyor)
        plc.close()
        plc = Plc(line.plc_port)
        first_seq = json.loads(jsonl_lines(line.results_dir)[-1])["sequence"] + 1
        wait_for(lambda: len(sub.results()) == n, "the result spooled under the wrong password", 20)
        baseline = []
        for i, face in enumerate((0, 0, 1, 1, 1)):
            p = run_part(plc, conveyor, n + 1, 260010 + i, face=face)
            n += 1
            assert p["state"] == DONE
            if face:
                baseline.append(p["cycle_s"])
            wait_for(lambda: len(sub.results()) == n, f"result {n} at the subscriber", 10)
        outage_phase(line, broker, plc, conveyor, sub, n + 1, a.outage_parts, baseline)
        n += a.outage_parts
        for i in range(2):
            assert run_part(plc, conveyor, n + 1, 260200 + i)["state"] == DONE
            n += 1
            wait_for(lambda: len(sub.results()) == n, f"result {n} at the subscriber", 10)
        lines = jsonl_lines(line.results_dir)
        assert len(lines) == n, f"{n} parts, {len(lines)} lines in the results files"
        check_delivery(sub, lines)
        check_metrics(line, lines, first_seq)
        check_retained_and_will(line, broker)
        plc.close()
        conveyor.close()
        ok = True
    finally:
        if sub:
            sub.close()
        line.stop()
        broker.stop()
        if not ok:
            print_logs(workdir)
        elif not a.out:
            shutil.rmtree(workdir, ignore_errors=True)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
