"""Benchmark of the live loop: host-side overhead per step, round trips over a pseudo-terminal,
and Algorithm 1 run live (steps, knob travel, offset error) against `hyst sim-robot`.

Run: ``python bench/bench_live.py`` (about 3 min; ``--seeds N`` for the offline accuracy
section, 10 by default). Target (issue 4): host-side overhead per step, excluding the device's
own time, under 1 ms; the live offset within 0.5 deg of the twin's true shift.

The robot is the catheter `hyst sim-robot` serves: the calibrated one of `hyst simulate`
(``calibration.calibrated_catheter``) with its default effects (creep, friction, rate,
coupling) unless a line says ``none``. The search is what `hyst detect-shift --port` runs:
``device.open_probe`` with its defaults (step-and-dwell: each 0.5 deg step holds 0.35 s and reads
the mean current of the last 0.3 s, protocol features ``dwell`` and ``mean``), thresholds from
the model's identification.

1. host overhead: the driver talks to the device-side protocol handler in-process through a
   pyserial-like object; the time spent inside the device (handler + twin) is measured and
   subtracted, leaving encode + write + read + decode + checks on the host;
2. round trip over a real pty with ``hyst sim-robot`` in another process (what a step costs end
   to end: pty, device, twin; the emulator does not wait out the simulated motion and dwell);
3. detect-shift live over a pty to ``hyst sim-robot`` per shape: steps, knob travel, error;
4. accuracy over many seeds: the same emulator and driver code in-process (a pty only adds
   transport time, the numbers are the same), 10 seeds x 4 shapes x 2 knobs per catheter and
   effect set: the offset error against ``true_offsets`` (paper eqs. 1-4);
5. why step-and-dwell: the same searches with single instantaneous samples and with the mean
   current taken while the knob moves, with and without the default effects: the noise of one
   sample, and the late edge of a moving reading (the ``rate`` effect's lag of the tendon
   behind the knob, tau = 25 ms, plus the causal filter's delay: speed x lag);
6. host-side overhead per step of the whole search (Algorithm 1's own computation + driver),
   the device's time subtracted (in-process port, no pty).
"""
from __future__ import annotations

import argparse
import select
import signal
import subprocess
import sys
import time

import math

import numpy as np

from hystcli.errors import ShiftDetectionError

from hystcli.sim.calibration import calibrated_catheter
from hystcli.device import (DEFAULT_DWELL, DEFAULT_MEAN, Device, DeviceProbe, decode_frame,
                            encode_frame, open_probe)
from hystcli.device.emulator import DeviceEmulator
from hystcli.core.model import Model
from hystcli.core.params import Shape
from hystcli.shift import detect_shift
from hystcli.sim.experiment import identify_catheter
from hystcli.sim.live import LiveTwin
from hystcli.sim.scenarios import record_sweep

N = 3000
SHAPES = ("straight", "alpha=45,theta=0", "alpha=90,theta=180", "alpha=45,theta=0;alpha=45,theta=90")


class DirectPort:
    """pyserial-like: write() hands each line to the device handler at once, timing it."""

    def __init__(self, emu: DeviceEmulator) -> None:
        self.emu = emu
        self.out = bytearray()
        self.device_time = 0.0
        self.timeout = None

    @property
    def in_waiting(self) -> int:
        return len(self.out)

    def write(self, data: bytes) -> int:
        t0 = time.perf_counter()
        for line in data.splitlines(keepends=True):
            for reply, _ in self.emu.handle_line(line):
                self.out += reply
        self.device_time += time.perf_counter() - t0
        return len(data)

    def read(self, n: int = 1) -> bytes:
        chunk = bytes(self.out[:n])
        del self.out[:n]
        return chunk


def identified_model(cat) -> Model:
    """The catheter's straight-shaft model as the paper identifies it (``hyst demo``'s path): one
    recorded sweep per knob through identification, so detect-shift reads the calibration record
    a user's model file would hold."""
    return identify_catheter({k: record_sweep(cat, k) for k in (1, 2)}, cat.name)


def direct_device(cat, shape: str = "straight", effects=None, seed: int = 0) -> tuple[Device, DirectPort]:
    port = DirectPort(DeviceEmulator(LiveTwin(cat, shape=Shape.parse(shape), effects=effects, seed=seed)))
    return Device(port, timeout=1.0), port


def host_overhead() -> None:
    cat = calibrated_catheter("ice-a")
    dev, port = direct_device(cat)
    qs = 10 * np.sin(np.linspace(0, 20 * np.pi, N))
    per = []
    for q in qs:
        d0 = port.device_time
        t0 = time.perf_counter()
        dev.move(1, float(q), 20.0)
        per.append((time.perf_counter() - t0) - (port.device_time - d0))
    per_us = np.array(per) * 1e6
    print(f"1. host-side overhead per MOVE ({N} plain MOVEs, device time subtracted):")
    print(f"   median {np.median(per_us):7.1f} us   p99 {np.percentile(per_us, 99):7.1f} us   "
          f"max {per_us.max():7.1f} us   (target < 1000 us)")
    t0 = time.perf_counter()
    for i in range(N):
        encode_frame(i, "MOVE", 1, 1.2345, 20.0, "dwell=0.3500", "mean=0.3000")
    enc = (time.perf_counter() - t0) / N * 1e6
    frame = encode_frame(7, "POS", 1, 1.2345, 130.25, 0.75, "qmean=1.2345", "cmean=130.1000", "tmean=0.3000")
    t0 = time.perf_counter()
    for _ in range(N):
        decode_frame(frame)
    dec = (time.perf_counter() - t0) / N * 1e6
    print(f"   of which: encode {enc:.1f} us (step-and-dwell MOVE), decode {dec:.1f} us "
          "(POS with the mean) per frame")
    probe = DeviceProbe(dev, 1, current_ceiling=5000.0)
    per, dev_ms = [], []
    for q in np.arange(0, 20, 0.5):
        d0 = port.device_time
        t0 = time.perf_counter()
        probe.step_to(float(q))
        per.append((time.perf_counter() - t0) - (port.device_time - d0))
        dev_ms.append(port.device_time - d0)
    print(f"   DeviceProbe.step_to (step-and-dwell, averaged={probe.averaged}) host overhead: median "
          f"{np.median(per) * 1e6:.1f} us; the emulator's own compute per step {np.median(dev_ms) * 1e3:.1f} ms")


def start_sim_robot(*args: str) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([sys.executable, "-m", "hystcli", "sim-robot", "--quiet", *args],
                            stdout=subprocess.PIPE, text=True)
    ready, _, _ = select.select([proc.stdout], [], [], 60)
    if not ready:
        proc.kill()
        raise SystemExit("sim-robot did not start")
    return proc, proc.stdout.readline().strip()


def stop(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGTERM)
    proc.wait(timeout=20)


def pty_round_trip() -> None:
    for latency in ("0", "2"):
        proc, path = start_sim_robot("--latency-ms", latency)
        try:
            with Device(path, timeout=1.0) as dev:
                qs = 10 * np.sin(np.linspace(0, 4 * np.pi, 500))
                per = []
                for q in qs:
                    t0 = time.perf_counter()
                    dev.move(1, float(q), 20.0)
                    per.append(time.perf_counter() - t0)
                per_ms = np.array(per) * 1e3
                dwell = []
                for q in np.arange(0.5, 10.5, 0.5):
                    t0 = time.perf_counter()
                    dev.move(1, float(q), 5.0, dwell=DEFAULT_DWELL, mean=DEFAULT_MEAN)
                    dwell.append(time.perf_counter() - t0)
        finally:
            stop(proc)
        print(f"2. round trip over a pty to `hyst sim-robot --latency-ms {latency}` (device and twin "
              f"included): plain MOVE (500) median {np.median(per_ms):.3f} ms, p99 "
              f"{np.percentile(per_ms, 99):.3f} ms; step-and-dwell MOVE (20) median "
              f"{np.median(dwell) * 1e3:.2f} ms")


def live_detect_over_pty(seeds: int = 3) -> None:
    cat = calibrated_catheter("ice-a")
    model = identified_model(cat)
    print(f"3. detect-shift --port path (open_probe per knob, defaults: step 0.5 deg, speed 5 deg/s, "
          f"dwell {DEFAULT_DWELL:g} s, mean {DEFAULT_MEAN:g} s; default travel limit) over a pty to "
          f"`hyst sim-robot` (ice-a, default effects), seeds 0-{seeds - 1}:")
    print(f"   {'shape':38s} knob  steps(mean/max)  travel deg(mean/max)  err mean  |err| max  "
          "wall ms/step")
    for shape in SHAPES:
        true = cat.true_offsets(Shape.parse(shape))
        rows = {k: [] for k in (1, 2)}
        for seed in range(seeds):
            proc, path = start_sim_robot("--shape", shape, "--seed", str(seed))
            try:
                for k in (1, 2):
                    probe = open_probe(path, 115200, k, speed=5.0, current_ceiling=2000.0)
                    try:
                        t0 = time.perf_counter()
                        r = detect_shift(model, probe, k)
                        el = time.perf_counter() - t0
                    finally:
                        probe.device.close()
                    rows[k].append((r.steps, r.travel, r.offset - true[k], el / (r.steps + 1)))
            finally:
                stop(proc)
        for k, vals in rows.items():
            a = np.array(vals)
            print(f"   {shape:38s} {k:4d}  {a[:, 0].mean():6.1f}/{a[:, 0].max():3.0f}"
                  f"       {a[:, 1].mean():6.1f}/{a[:, 1].max():5.1f}      {a[:, 2].mean():+6.3f}"
                  f"   {np.abs(a[:, 2]).max():8.3f}  {a[:, 3].mean() * 1e3:9.2f}")


def search_errors(cat, effects, seeds, speed: float = 5.0, dwell=DEFAULT_DWELL, mean=DEFAULT_MEAN,
                  shapes=SHAPES) -> list[tuple[str, int, int, float, int, float]]:
    """(shape, seed, knob, error, steps, travel) of every search, in-process."""
    model = identified_model(cat)
    out = []
    for shape in shapes:
        true = cat.true_offsets(Shape.parse(shape))
        for seed in seeds:
            dev, _ = direct_device(cat, shape, effects, seed)
            for k in (1, 2):
                probe = DeviceProbe(dev, k, current_ceiling=2000.0, speed=speed, dwell=dwell, mean=mean)
                try:
                    r = detect_shift(model, probe, k)
                except ShiftDetectionError:   # refused: counted, no error to average
                    out.append((shape, seed, k, math.nan, 0, math.nan))
                    continue
                out.append((shape, seed, k, r.offset - true[k], r.steps, r.travel))
    return out


def accuracy_offline(seeds: int) -> None:
    print(f"4. offset error over seeds 0-{seeds - 1} x {len(SHAPES)} shapes x 2 knobs (the emulator "
          "and driver in-process; step-and-dwell defaults, 5 deg/s, the default travel limit):")
    print(f"   {'catheter':9s} {'effects':8s} {'n':>4s}  err mean   std   |err| max  at (shape, seed, knob)")
    worst_all = 0.0
    for name in ("ice-a", "ice-b"):
        cat = calibrated_catheter(name)
        for label, effects in (("default", None), ("none", ())):
            rows = [r for r in search_errors(cat, effects, range(seeds)) if not math.isnan(r[3])]
            e = np.array([r[3] for r in rows])
            w = max(rows, key=lambda r: abs(r[3]))
            worst_all = max(worst_all, abs(w[3]))
            print(f"   {name:9s} {label:8s} {len(rows):4d}  {e.mean():+7.3f} {e.std():6.3f}  {abs(w[3]):8.3f}"
                  f"   ({w[0]}, {w[1]}, {w[2]})")
    print(f"   worst |error| over all: {worst_all:.3f} deg (target 0.5)")


def probe_modes(seeds: int = 3) -> None:
    cat = calibrated_catheter("ice-a")
    print(f"5. probe readings compared (ice-a, 5 deg/s: a 0.5 deg step moves for 0.1 s; seeds "
          f"0-{seeds - 1} x {len(SHAPES)} shapes x 2 knobs):")
    print(f"   {'reading':44s} {'effects':8s} err mean   std   |err| max")
    modes = (("single sample on arrival (base protocol)", None, None),
             ("mean over the step's motion (mean=0.1)", 0.0, 0.1),
             (f"step-and-dwell (dwell={DEFAULT_DWELL:g}, mean={DEFAULT_MEAN:g})", DEFAULT_DWELL, DEFAULT_MEAN))
    for label, dwell, mean in modes:
        for eff_label, effects in (("default", None), ("none", ())):
            e = np.array([r[3] for r in search_errors(cat, effects, range(seeds), dwell=dwell, mean=mean)])
            refused = int(np.isnan(e).sum())
            e = e[~np.isnan(e)]
            print(f"   {label:44s} {eff_label:8s} {e.mean():+7.3f} {e.std():6.3f}  {np.abs(e).max():8.3f}"
                  + (f"   ({refused} refused)" if refused else ""))
    print("   (a positive mean error is an edge read late; the rate effect's lag alone: "
          "5 deg/s x 25 ms = 0.125 deg)")


def search_host_overhead() -> None:
    cat = calibrated_catheter("ice-a")
    model = identified_model(cat)
    print("6. host-side overhead per step of the whole search (Algorithm 1 + driver), device time "
          "subtracted (in-process port, no pty), steps and travel per knob:")
    for shape in SHAPES:
        dev, port = direct_device(cat, shape)
        per, info = [], []
        for k in (1, 2):
            probe = DeviceProbe(dev, k)
            d0 = port.device_time
            t0 = time.perf_counter()
            r = detect_shift(model, probe, k)
            host = (time.perf_counter() - t0) - (port.device_time - d0)
            moves = r.steps + 1  # the return home is one more MOVE
            per.append(host / moves)
            info.append(f"knob {k}: {r.steps} steps, {r.travel:.1f} deg")
        print(f"   {shape:38s} host {np.mean(per) * 1e6:7.1f} us/step (knob 1 {per[0] * 1e6:.1f}, "
              f"knob 2 {per[1] * 1e6:.1f}; target < 1000 us)   {'; '.join(info)}")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10, help="seeds of the offline accuracy section")
    args = ap.parse_args()
    host_overhead()
    pty_round_trip()
    live_detect_over_pty()
    accuracy_offline(args.seeds)
    probe_modes()
    search_host_overhead()
