#!/usr/bin/python3
"""pymodbus (Debian's python3-pymodbus 3.0) as the line PLC against `hotgauge plc serve`.

Checks the contract of docs/plc-modbus.md with a client that is not ours: the heartbeat
advances, trigger -> BUSY -> DONE -> ack -> IDLE, every hub-a feature decoded as int32 µm and
float32 mm with pymodbus's own payload decoder in both word orders and compared with the
stand-in cell's documented values, the holding mirror, results frozen while DONE, a trigger
refused while BUSY, NOK / not measured / degraded parts, FAULT -> reset, and exceptions.

    /usr/bin/python3 plc_pymodbus_test.py HOTGAUGE_BINARY
"""
import math
import re
import os
import signal
import subprocess
import sys
import tempfile
import time

import yaml
from pymodbus.client import ModbusTcpClient
from pymodbus.constants import Endian
from pymodbus.payload import BinaryPayloadBuilder, BinaryPayloadDecoder

BIN = sys.argv[1]
RECIPE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "config", "parts",
                      "hub-a.yaml")
UNIT = 1
N_INPUTS = 123
IDLE, BUSY, DONE, FAULT = 1, 2, 3, 4
TRIGGER, ACK, RESET = 1, 2, 3
INVALID = -0x80000000


def wait_for(predicate, what, timeout=5.0):
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.02)


class Server:
    """hotgauge plc serve on 127.0.0.1, an ephemeral port, stopped with SIGTERM."""

    def __init__(self, tmp, *args):
        self.port_file = os.path.join(tmp, "port")
        if os.path.exists(self.port_file):
            os.remove(self.port_file)
        self.log = open(os.path.join(tmp, "serve.log"), "w")
        self.proc = subprocess.Popen(
            [BIN, "plc", "serve", "--bind", "127.0.0.1", "--port", "0", "--port-file",
             self.port_file, "--busy-ms", "100", *args],
            stdout=self.log, stderr=subprocess.STDOUT)
        wait_for(lambda: os.path.exists(self.port_file) or self.proc.poll() is not None,
                 "the port file")
        assert self.proc.poll() is None, "plc serve exited at start"
        self.port = int(open(self.port_file).read())

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.proc.send_signal(signal.SIGTERM)
        rc = self.proc.wait(timeout=10)
        self.log.close()
        if exc[0] is None:
            assert rc == 0, f"plc serve exited with {rc}"


class Plc:
    def __init__(self, port, wordorder):
        self.wordorder = wordorder
        self.client = ModbusTcpClient("127.0.0.1", port=port, timeout=2)
        assert self.client.connect(), "cannot connect"

    def close(self):
        self.client.close()

    def inputs(self, address=0, count=N_INPUTS):
        rr = self.client.read_input_registers(address, count, slave=UNIT)
        assert not rr.isError(), f"read input {address} x {count}: {rr}"
        return rr.registers

    def holding(self, address, count):
        rr = self.client.read_holding_registers(address, count, slave=UNIT)
        assert not rr.isError(), f"read holding {address} x {count}: {rr}"
        return rr.registers

    def write(self, address, values):
        rr = self.client.write_registers(address, values, slave=UNIT)
        assert not rr.isError(), f"write {address}: {rr}"

    def decoder(self, registers):
        return BinaryPayloadDecoder.fromRegisters(registers, byteorder=Endian.Big,
                                                  wordorder=self.wordorder)

    def i32(self, registers):
        return self.decoder(registers).decode_32bit_int()

    def u32(self, registers):
        return self.decoder(registers).decode_32bit_uint()

    def f32(self, registers):
        return self.decoder(registers).decode_32bit_float()

    def u32_registers(self, value):
        b = BinaryPayloadBuilder(byteorder=Endian.Big, wordorder=self.wordorder)
        b.add_32bit_uint(value)
        return b.to_registers()

    def state(self):
        return self.inputs(1, 1)[0]

    def trigger(self, part, slot=1, face=0, die=3):
        """One FC16 of holding 0..6: command, part id, recipe slot, face, PLC heartbeat, die."""
        self.write(0, [TRIGGER, *self.u32_registers(part), slot, face, part & 0xFFFF, die])

    def exception(self, response):
        assert response.isError(), f"expected an exception, got {response}"
        return response.exception_code


def features_of(registers, plc):
    """slot -> (um, mm, verdict) for every slot of one full-map read."""
    out = {}
    for slot in range(1, 17):
        a = 16 + 6 * (slot - 1)
        out[slot] = (plc.i32(registers[a:a + 2]), plc.f32(registers[a + 2:a + 4]),
                     registers[a + 4])
    return out


def expected(recipe, part):
    """The stand-in cell: nominal + ((part + slot) mod 5 - 2) * 10 µm held inside the
    tolerance (a die shift is never below 0), all OK."""
    def dev(f):
        lo, hi = (round(x * 1000) for x in f["tolerance_mm"])
        return min(max(((part + f["slot"]) % 5 - 2) * 10, lo), hi)
    return {f["slot"]: round(f["nominal_mm"] * 1000) + dev(f) for f in recipe["features"]}


def cycle(plc, part, slot=1):
    """trigger -> BUSY -> DONE; returns the full map read in DONE (not yet acked)."""
    plc.trigger(part, slot)
    status = plc.inputs(0, 12)
    assert status[1] == BUSY, f"state after trigger: {status[1]}"
    assert status[3] == 0, f"command status after trigger: {status[3]}"
    assert plc.u32(status[6:8]) == part, "part id echo"
    wait_for(lambda: plc.state() in (DONE, FAULT), "DONE")
    return plc.inputs()


def check_order(tmp, recipe, name, wordorder):
    with Server(tmp, "--word-order", name) as server:
        plc = Plc(server.port, wordorder)
        # Heartbeat: ours advances by itself; the PLC's is echoed.
        h0 = plc.inputs(0, 1)[0]
        wait_for(lambda: (plc.inputs(0, 1)[0] - h0) % 65536 >= 3, "the heartbeat to advance")
        plc.write(5, [321])
        assert plc.inputs(10, 1)[0] == 321, "PLC heartbeat echo"
        assert plc.inputs()[1] == IDLE and plc.inputs()[14] == 4, "IDLE, map version 4"

        # A full cycle, with a refused trigger while BUSY.
        part = 4242 + 70000  # above 65535: both words of the part id carry bits
        plc.trigger(part)
        assert plc.state() == BUSY
        assert plc.inputs(112, 1)[0] == 1, "scan phase: scanning"
        t_trigger = time.time()
        plc.trigger(part + 1)
        status = plc.inputs(0, 8)
        assert status[3] == 101, f"trigger while BUSY: command status {status[3]}"
        assert plc.u32(status[6:8]) == part, "the refused trigger changed the part id"
        # Scans done (the stand-in: halfway through its 300 ms) while still BUSY.
        wait_for(lambda: plc.inputs(112, 1)[0] == 2, "scan phase 2")
        assert plc.state() == BUSY, "scan phase 2 only came with DONE"
        wait_for(lambda: plc.state() == DONE, "DONE")
        regs = plc.inputs()
        assert regs[112] == 2 and regs[114] == 0, f"scan phase {regs[112]}, reasons {regs[114]}"
        assert abs(plc.u32(regs[115:117]) + regs[117] / 1000 - t_trigger) < 2, "result time"
        revision = subprocess.run([BIN, "plc", "map", "--recipe", RECIPE], check=True,
                                  capture_output=True, text=True).stdout
        assert f"revision {regs[118]} " in revision, (regs[118], revision.splitlines()[0])
        assert regs[119] == 0 and regs[120] == 65535, "the stand-in has no calibration"
        assert regs[5] == 1, f"sequence {regs[5]}"
        assert plc.u32(regs[6:8]) == part
        assert regs[8] == 1 and regs[9] == 0, "recipe slot / face echo"
        assert regs[10] == (part + 1) & 0xFFFF, "PLC heartbeat echo of the last write"
        assert regs[11] == 1, f"overall verdict {regs[11]}"
        assert regs[12] == 14, f"feature count {regs[12]}"
        assert regs[13] == 10500, f"temperature {regs[13]}"
        want = expected(recipe, part)
        got = features_of(regs, plc)
        for slot in range(1, 17):
            um, mm, verdict = got[slot]
            if slot in want:
                assert um == want[slot], f"slot {slot}: {um} µm, expected {want[slot]}"
                assert abs(mm - want[slot] / 1000) < 1e-4, f"slot {slot}: {mm} mm"
                assert verdict == 1, f"slot {slot}: verdict {verdict}"
            else:
                assert um == INVALID and math.isnan(mm) and verdict == 0, f"unused slot {slot}"
        # The mirror is the same image; the results do not change while DONE.
        mirror = plc.holding(100, N_INPUTS)
        assert mirror[1:] == regs[1:], "holding mirror differs from the input registers"
        time.sleep(0.3)  # not a wait for a condition: DONE must hold still over time
        assert plc.inputs()[1:] == regs[1:], "results changed while DONE"
        plc.write(0, [ACK])
        after = plc.inputs()
        assert after[1] == IDLE, "state after ack"
        assert all(v[0] == INVALID and v[2] == 0 for v in features_of(after, plc).values())
        assert after[11] == 0 and after[12] == 0, "stale verdict after ack"

        # NOK, not measured and degraded parts.
        regs = cycle(plc, 999997)
        got = features_of(regs, plc)
        nominal1 = round(recipe["features"][0]["nominal_mm"] * 1000)
        assert got[1][0] == nominal1 + 1000 and got[1][2] == 2, f"NOK feature {got[1]}"
        assert regs[21] >> 8 == 4 and regs[114] == 4, "reasons: outside tolerance"
        assert regs[11] == 2 and regs[5] == 2, "overall NOK, sequence 2"
        plc.write(0, [ACK])
        regs = cycle(plc, 999998)
        got = features_of(regs, plc)
        assert got[3][0] == INVALID and math.isnan(got[3][1]) and got[3][2] == 3, got[3]
        assert regs[33] >> 8 == 1 and regs[114] == 1, "reasons: not measured"
        assert regs[11] == 3, "overall not measured"
        plc.write(0, [ACK])
        regs = cycle(plc, 999996)
        assert regs[11] == 4, "overall degraded"
        got = features_of(regs, plc)
        nominal4 = round(recipe["features"][3]["nominal_mm"] * 1000)
        assert got[4][0] == nominal4 + 1000 and got[4][2] == 4, f"degraded, not NOK: {got[4]}"
        assert regs[39] >> 8 == 2 | 4 and regs[114] == 6, "reasons: degraded, outside tolerance"
        assert all(g[2] == 1 for s, g in got.items() if s <= 14 and s != 4)
        plc.write(0, [ACK])

        # FAULT: only a reset leaves it.
        regs = cycle(plc, 999999)
        assert regs[1] == FAULT and regs[2] == 201, f"fault {regs[1]} / {regs[2]}"
        assert regs[11] == 0 and plc.i32(regs[16:18]) == INVALID, "results shown in FAULT"
        plc.trigger(1)
        assert plc.inputs(3, 1)[0] == 103, "trigger in FAULT"
        plc.write(0, [ACK])
        assert plc.inputs(1, 3) == [FAULT, 201, 103], "ack in FAULT"
        plc.write(0, [RESET])
        assert plc.inputs(1, 3) == [IDLE, 0, 0], "reset"
        plc.trigger(5, slot=2)  # no recipe in slot 2: FAULT as soon as the cell hears of it
        wait_for(lambda: plc.state() == FAULT, "FAULT")
        assert plc.inputs(2, 1)[0] == 202, "unknown recipe slot"
        plc.write(0, [RESET])

        # Exceptions, and the connection stays usable after each.
        c = plc.client
        assert plc.exception(c.read_input_registers(N_INPUTS, 1, slave=UNIT)) == 2
        assert plc.exception(c.read_holding_registers(7, 1, slave=UNIT)) == 2
        assert plc.exception(c.write_register(7, 1, slave=UNIT)) == 2
        assert plc.exception(c.write_register(100, 1, slave=UNIT)) == 2
        assert plc.exception(c.read_input_registers(0, 126, slave=UNIT)) == 3
        assert plc.exception(c.read_coils(0, 8, slave=UNIT)) == 1
        assert plc.exception(c.read_input_registers(0, 1, slave=7)) == 0x0B
        documented_ranges_hold(plc)
        assert plc.state() == IDLE
        plc.close()


def documented_ranges_hold(plc):
    """docs/plc-modbus.md "Bad input": the addresses its table says are outside the map get
    exception 02, the ones either side of each border inside it are answered (issue 39: the table
    said input 112 and holding 212 while the map had grown to 122 and 222)."""
    doc = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "docs", "plc-modbus.md")
    text = open(doc, encoding="utf-8").read()
    m = re.search(r"read outside the map \(input ≥ (\d+), holding (\d+)–(\d+) or ≥ (\d+)", text)
    assert m, "docs/plc-modbus.md: the bad-input table's read row is not where this test reads it"
    first_input, hole_lo, hole_hi, first_holding = (int(g) for g in m.groups())
    c = plc.client
    assert not c.read_input_registers(first_input - 1, 1, slave=UNIT).isError()
    assert plc.exception(c.read_input_registers(first_input, 1, slave=UNIT)) == 2
    assert plc.exception(c.read_input_registers(first_input - 1, 2, slave=UNIT)) == 2
    assert not c.read_holding_registers(hole_lo - 1, 1, slave=UNIT).isError()
    for a in (hole_lo, hole_hi, first_holding):
        assert plc.exception(c.read_holding_registers(a, 1, slave=UNIT)) == 2, a
    assert not c.read_holding_registers(hole_hi + 1, 1, slave=UNIT).isError()
    assert not c.read_holding_registers(first_holding - 1, 1, slave=UNIT).isError()
    print(f"documented map borders hold: inputs < {first_input}, holdings < {hole_lo} and "
          f"{hole_hi + 1}-{first_holding - 1}")


def main():
    recipe = yaml.safe_load(open(RECIPE))
    with tempfile.TemporaryDirectory() as tmp:
        for name, order in (("big", Endian.Big), ("little", Endian.Little)):
            try:
                check_order(tmp, recipe, name, order)
            except AssertionError:
                print(f"FAIL ({name} word order); server log:")
                print(open(os.path.join(tmp, "serve.log")).read()[-3000:])
                raise
            print(f"PASS: pymodbus as the PLC, {name} word order")


if __name__ == "__main__":
    main()
