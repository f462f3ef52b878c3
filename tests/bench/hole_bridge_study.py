#!/usr/bin/python3
"""How well can an accelerometer record bridge its lost datagrams? (issue 38)

Punches 10 ms holes (random datagram loss) into the accelerometer records of an independent
recording, bridges them two ways, integrates (FFT, 1.5 Hz order-4 high-pass, as
compensate::integrate_twice) and compares the displacement with the independent simulator's own
truth (truth.json face_data[face].vibration: damped modes per blow plus ambient lines), by the
distance from the nearest hole:
  bridge   the gauge's least-squares box + ramp per hole (compensate::integrate_across_gaps)
  ar       each hole filled by linear prediction (least-squares AR(p), forward and backward,
           cross-faded), no bridge
  noloss   the whole record, for the floor
Usage: hole_bridge_study.py RECORDING_DIR(with truth.json) [LOSS=0.02] [AR_ORDER=40] [PATTERNS=4]
Research, not a test: it reads the truth the gauge never sees.
"""
import json
import sys

import numpy as np


def integrate(a, rate, hp=1.5, order=4, taper_s=0.25):
    n = len(a)
    a = a - a.mean()
    r = min(n // 4, int(taper_s * rate))
    w = 0.5 * (1 - np.cos(np.pi * (np.arange(r) + 0.5) / r))
    a = a.copy()
    a[:r] *= w
    a[n - r:] *= w[::-1]
    m = 2 * n
    f = np.fft.rfftfreq(m, 1 / rate)
    g = np.zeros_like(f)
    g[1:] = -1 / np.sqrt(1 + (hp / f[1:]) ** (2 * order)) / (2 * np.pi * f[1:]) ** 2
    return np.fft.irfft(np.fft.rfft(a, m) * g, m)[:n]


def bridge(a, rate, gaps):
    n = len(a)
    u = integrate(a, rate)
    if not gaps:
        return u
    cols = []
    for g0, g1 in gaps:
        box, ramp = np.zeros(n), np.zeros(n)
        box[g0:g1 + 1] = 1
        ramp[g0:g1 + 1] = np.arange(g0, g1 + 1) - 0.5 * (g0 + g1)
        cols += [integrate(box, rate), integrate(ramp, rate)]
    B = np.array(cols).T
    use = np.ones(n)
    e = min(n // 2, int(0.25 * rate))
    use[:e] = use[n - e:] = 0
    for g0, g1 in gaps:
        use[g0:g1 + 1] = 0
    BtB = B.T @ (B * use[:, None])
    BtB += 1e-12 * np.eye(len(BtB)) * np.trace(BtB) / len(BtB)
    return u + B @ np.linalg.solve(BtB, -(B.T @ (use * u)))


def ar_fit(x, ok, p):
    rows = [i for i in range(p, len(x)) if ok[i - p:i + 1].all()]
    X = np.array([x[i - p:i][::-1] for i in rows])
    c, *_ = np.linalg.lstsq(X, x[rows], rcond=None)
    return c


def ar_fill(x, gaps, p):
    ok = np.ones(len(x), bool)
    for g0, g1 in gaps:
        ok[g0:g1 + 1] = False
    cf, cb = ar_fit(x, ok, p), ar_fit(x[::-1], ok[::-1], p)
    y = x.copy()
    n = len(x)
    for g0, g1 in gaps:
        if g0 < p or g1 + p >= n:
            continue
        fw = y.copy()
        for i in range(g0, g1 + 1):
            fw[i] = fw[i - p:i][::-1] @ cf
        xr = y[::-1].copy()
        for j in range(n - 1 - g1, n - g0):
            xr[j] = xr[j - p:j][::-1] @ cb
        t = (np.arange(g1 - g0 + 1) + 1) / (g1 - g0 + 2)
        y[g0:g1 + 1] = (1 - t) * fw[g0:g1 + 1] + t * xr[::-1][g0:g1 + 1]
    return y


def smoothstep(x):
    x = np.clip(x, 0, 1)
    return x ** 3 * (10 - 15 * x + 6 * x * x)


def truth_u_mm(vib, t):  # t: s from vib["time_reference_ns"]; (3, n) world mm
    u = np.zeros((3, len(t)))
    for b in vib["blows"]:
        tau = t - b["t_s"]
        on = tau > 0
        for j, c in enumerate(b["components"]):
            m = vib["modes"][j // 3]
            w = 2 * np.pi * m["f_hz"]
            z = m["zeta"]
            u[c["axis"], on] += (c["amp_mm"] * np.exp(-z * w * tau[on]) *
                                 np.sin(w * np.sqrt(1 - z * z) * tau[on] + c["phase"]) *
                                 smoothstep(tau[on] / m["rise_s"]))
    for k, ax in enumerate(vib["ambient"]["axes"]):
        for f, A, ph in zip(ax["f_hz"], ax["amp_mm"], ax["phase"]):
            u[k] += A * np.sin(2 * np.pi * f * t + ph)
    return u


def world_accel(d, fd):
    """A face's accelerometer record (folder d, truth face_data fd) in world axes, resampled to a
    uniform grid: (first sample's time in ns, grid step in s, (3, n) m/s²)."""
    a = np.load(d + "/accel.npy").astype(float)
    t_ns = np.load(d + "/accel_times.npy").astype(np.int64)
    R = np.array(fd["camera_to_world"])[:3, :3] @ np.array(fd["accel_to_camera"])
    aw = a @ R.T
    ts = (t_ns - t_ns[0]) / 1e9
    per = np.median(np.diff(ts))
    tg = np.arange(int(ts[-1] / per) + 1) * per
    return t_ns[0], per, np.array([np.interp(tg, ts, aw[:, k]) for k in range(3)])


def straight_fill(x, gaps):
    """x (one axis) with a straight line over each gap, as the gauge fills it before bridging."""
    lin = x.copy()
    for g0, g1 in gaps:
        lin[g0:g1 + 1] = np.interp(np.arange(g0, g1 + 1), [g0 - 1, g1 + 1], [x[g0 - 1], x[g1 + 1]])
    return lin


def holes(n, loss, rng, per_datagram=20):
    lost = rng.random(n // per_datagram) < loss
    gaps, i = [], 0
    while i < len(lost):
        if lost[i]:
            j = i
            while j + 1 < len(lost) and lost[j + 1]:
                j += 1
            if i > 0 and j < len(lost) - 1:
                gaps.append((i * per_datagram, (j + 1) * per_datagram - 1))
            i = j + 1
        else:
            i += 1
    return gaps


def main():
    rec = sys.argv[1]
    loss = float(sys.argv[2]) if len(sys.argv) > 2 else 0.02
    p = int(sys.argv[3]) if len(sys.argv) > 3 else 40
    patterns = int(sys.argv[4]) if len(sys.argv) > 4 else 4
    truth = json.load(open(rec + "/truth.json"))
    bins = [0, 0.05, 0.1, 0.2, 0.3, 0.5, 0.8, 9]
    errors = {}
    for face, fd in truth["face_data"].items():
        d = f"{rec}/part/{face}"
        pt = np.load(d + "/profile_times.npy").astype(np.int64)
        t0_ns, per, g = world_accel(d, fd)
        n = g.shape[1]
        tg = np.arange(n) * per
        vib = fd["vibration"]
        u_true = truth_u_mm(vib, tg + (t0_ns - vib["time_reference_ns"]) / 1e9) / 1000
        scan = (tg >= (pt[0] - t0_ns) / 1e9) & (tg <= (pt[-1] - t0_ns) / 1e9)
        rng = np.random.default_rng(sum(map(ord, face)))
        for _ in range(patterns):
            gaps = holes(n, loss, rng)
            lin = [straight_fill(g[k], gaps) for k in range(3)]
            est = {"noloss": [integrate(g[k], 1 / per) for k in range(3)],
                   "bridge": [bridge(lin[k], 1 / per, gaps) for k in range(3)],
                   "ar": [integrate(ar_fill(lin[k], gaps, p), 1 / per) for k in range(3)]}
            dist = np.full(n, 9.0)
            for g0, g1 in gaps:
                dist = np.minimum(dist, np.maximum(0, np.maximum(tg[g0] - tg, tg - tg[g1])))
            for name, u in est.items():
                errors.setdefault(name, []).append(
                    (np.abs(np.array(u) - u_true)[:, scan] * 1e6, dist[scan]))
    print(f"{rec}: {loss:.0%} of 10 ms datagrams lost, {patterns} patterns per face; "
          "|u_est - u_true| RMS / worst in µm by distance from the nearest hole (s)")
    print("%-8s" % "" + "".join("%14s" % f"{b0}-{b1}" for b0, b1 in zip(bins[:-1], bins[1:])))
    for name, v in errors.items():
        e = np.concatenate([x[0] for x in v], axis=1)
        dd = np.concatenate([x[1] for x in v])
        row = []
        for b0, b1 in zip(bins[:-1], bins[1:]):
            m = (dd >= b0) & (dd < b1)
            row.append("%6.1f/%6.1f " % (np.sqrt((e[:, m] ** 2).mean()), e[:, m].max())
                       if m.any() else "%14s" % "-")
        print("%-8s" % name + "".join(row))


if __name__ == "__main__":
    main()
