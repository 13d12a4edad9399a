"""Benchmark of the live loop: host-side overhead per step, round trips over a pseudo-terminal,
and Algorithm 1 run live (steps, knob travel, offset error) against `hyst sim-robot`.

Run: ``python bench/bench_live.py`` (about 20 s). Target (issue 4): host-side overhead per step,
excluding the device's own time, under 1 ms.

1. host overhead: the driver talks to the device-side protocol handler in-process through a
   pyserial-like object; the time spent inside the device (handler + twin) is measured and
   subtracted, leaving encode + write + read + decode + checks on the host;
2. round trip over a real pty with ``hyst sim-robot`` in another process (what a step costs end
   to end: pty, device, twin), and the same with a DeviceProbe step;
3. detect-shift live over the pty per shape: steps, travel, time, offset error;
4. the search as `hyst detect-shift --port` runs it (model thresholds from the identification,
   default options, one connection per knob) over a pty to `hyst sim-robot`: total knob travel
   and steps per shape, offset error over several seeds at the device's default knob speed
   (20 deg/s) and at 5 deg/s (the causal 20 Hz current filter lags ~16 ms, i.e. ~0.3 deg at
   20 deg/s, in the direction of motion);
5. host-side overhead per step of the whole search (Algorithm 1's own computation + driver:
   encode, write, read, decode, checks), the device's time subtracted (in-process port).
"""
from __future__ import annotations

import select
import signal
import subprocess
import sys
import time

import numpy as np

from hystcli.device import Device, DeviceProbe, decode_frame, encode_frame
from hystcli.emulator import DeviceEmulator
from hystcli.model import Shape
from hystcli.twin import LiveTwin, get_catheter

N = 3000


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


def host_overhead() -> None:
    cat = get_catheter("ice-a")
    port = DirectPort(DeviceEmulator(LiveTwin(cat, seed=0)))
    dev = Device(port, timeout=1.0)
    qs = 10 * np.sin(np.linspace(0, 20 * np.pi, N))
    port.device_time = 0.0
    per = []
    for q in qs:
        d0 = port.device_time
        t0 = time.perf_counter()
        dev.move(1, float(q), 20.0)
        per.append((time.perf_counter() - t0) - (port.device_time - d0))
    per_us = np.array(per) * 1e6
    print(f"1. host-side overhead per MOVE step ({N} steps, device time subtracted):")
    print(f"   median {np.median(per_us):7.1f} us   p99 {np.percentile(per_us, 99):7.1f} us   "
          f"max {per_us.max():7.1f} us   (target < 1000 us)")
    t0 = time.perf_counter()
    for i in range(N):
        encode_frame(i, "MOVE", 1, 1.2345, 20.0)
    enc = (time.perf_counter() - t0) / N * 1e6
    frame = encode_frame(7, "POS", 1, 1.2345, 130.25, 0.75)
    t0 = time.perf_counter()
    for _ in range(N):
        decode_frame(frame)
    dec = (time.perf_counter() - t0) / N * 1e6
    print(f"   of which: encode {enc:.1f} us, decode {dec:.1f} us per frame")
    probe = DeviceProbe(dev, 1, current_ceiling=5000.0)
    per = []
    for q in np.arange(0, 20, 0.5):
        d0 = port.device_time
        t0 = time.perf_counter()
        probe.step_to(float(q))
        per.append((time.perf_counter() - t0) - (port.device_time - d0))
    print(f"   DeviceProbe.step_to host overhead: median {np.median(per) * 1e6:.1f} us")


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
        finally:
            stop(proc)
        print(f"2. round trip over a pty to `hyst sim-robot --latency-ms {latency}` (500 MOVEs, "
              f"device and twin included): median {np.median(per_ms):.3f} ms, "
              f"p99 {np.percentile(per_ms, 99):.3f} ms")


def live_detect_shift() -> None:
    from hystcli.shift import detect_shift

    cat = get_catheter("ice-a")
    model = cat.true_model()
    print("3. Algorithm 1 live over a pty (`hyst sim-robot`, ice-a, seed 2; eps_lower 2, "
          "eps_upper 30 mA/deg, step 0.5 deg, current_dead_zone = no-load 120 mA):")
    print(f"   {'shape':38s} knob  offset  true   error  steps  travel  ms/step")
    for shape in ("straight", "alpha=45,theta=0", "alpha=90,theta=0", "alpha=45,theta=0;alpha=45,theta=90"):
        proc, path = start_sim_robot("--shape", shape, "--seed", "2")
        try:
            with Device(path, timeout=1.0) as dev:
                for k in (1, 2):
                    probe = DeviceProbe(dev, k, current_ceiling=2000.0)
                    t0 = time.perf_counter()
                    try:
                        r = detect_shift(model, probe, k, eps_lower=2.0, eps_upper=30.0,
                                         current_dead_zone=cat.current.no_load, max_travel=60.0)
                    except Exception as exc:  # noqa: BLE001 - report and go on
                        print(f"   {shape:38s} {k}     failed: {exc}")
                        continue
                    el = time.perf_counter() - t0
                    true = cat.true_offsets(Shape.parse(shape))[k]
                    print(f"   {shape:38s} {k}   {r.offset:6.2f} {true:6.2f} {r.offset - true:+6.2f} "
                          f"{r.steps:6d} {r.travel:7.1f} {el / max(r.steps, 1) * 1e3:8.2f}")
        finally:
            stop(proc)


SHAPES = ("straight", "alpha=45,theta=0", "alpha=90,theta=180", "alpha=45,theta=0;alpha=45,theta=90")


def identified_model(cat=None):
    """The twin's straight-shaft model with the identification `hyst identify` stores for
    detect-shift (dead-zone slope ~0.5 mA/deg, loaded k_load, dead-zone current = no-load)."""
    from hystcli.model import KnobIdentification, Model

    cat = cat or get_catheter("ice-a")
    ident = {k: KnobIdentification(slope_dead_zone=0.5, slope_loaded=cat.current.k_load, q_min=-40.0,
                                   q_max=40.0, current_dead_zone=cat.current.no_load) for k in (1, 2)}
    return Model(dict(cat.knobs), cat.geometry, identification=ident)


def cli_search_over_pty(seeds: int = 5) -> None:
    from hystcli.device import open_probe
    from hystcli.shift import detect_shift

    cat = get_catheter("ice-a")
    model = identified_model(cat)
    print(f"4. detect-shift --port path (open_probe per knob, thresholds from the model, step 0.5 deg, "
          f"max-travel 40) over a pty to `hyst sim-robot`, ice-a, seeds 0-{seeds - 1}:")
    print(f"   {'shape':38s} knob speed  steps(mean/max) travel(mean/max)  err mean  |err| max  ms/step")
    for shape in SHAPES:
        true = cat.true_offsets(Shape.parse(shape))
        rows = {(k, sp): [] for k in (1, 2) for sp in (None, 5.0)}
        for seed in range(seeds):
            for speed in (None, 5.0):
                proc, path = start_sim_robot("--shape", shape, "--seed", str(seed))
                try:
                    for k in (1, 2):
                        probe = open_probe(path, 115200, k, speed=speed)
                        try:
                            t0 = time.perf_counter()
                            r = detect_shift(model, probe, k, max_travel=40.0)
                            el = time.perf_counter() - t0
                        finally:
                            probe.device.close()
                        rows[(k, speed)].append((r.steps, r.travel, r.offset - true[k], el / (r.steps + 1)))
                finally:
                    stop(proc)
        for (k, speed), vals in rows.items():
            a = np.array(vals)
            print(f"   {shape:38s} {k:4d} {speed or 20:5.0f}  {a[:, 0].mean():6.1f}/{a[:, 0].max():3.0f}"
                  f"     {a[:, 1].mean():6.1f}/{a[:, 1].max():5.1f}     {a[:, 2].mean():+6.2f}"
                  f"   {np.abs(a[:, 2]).max():8.2f}  {a[:, 3].mean() * 1e3:7.2f}")


def search_host_overhead() -> None:
    from hystcli.shift import detect_shift

    cat = get_catheter("ice-a")
    model = identified_model(cat)
    print("5. host-side overhead per step of the whole search (Algorithm 1 + driver), device time "
          "subtracted (in-process port, no pty):")
    for shape in SHAPES:
        port = DirectPort(DeviceEmulator(LiveTwin(cat, shape=Shape.parse(shape), seed=0)))
        dev = Device(port, timeout=1.0)
        per, steps = [], 0
        for k in (1, 2):
            probe = DeviceProbe(dev, k)
            d0 = port.device_time
            t0 = time.perf_counter()
            r = detect_shift(model, probe, k, max_travel=40.0)
            host = (time.perf_counter() - t0) - (port.device_time - d0)
            moves = r.steps + 1  # the return home is one more MOVE
            per.append(host / moves)
            steps += moves
        print(f"   {shape:38s} {steps:4d} MOVEs   host {np.mean(per) * 1e6:7.1f} us/step "
              f"(knob 1 {per[0] * 1e6:.1f}, knob 2 {per[1] * 1e6:.1f})   target < 1000 us")


if __name__ == "__main__":
    host_overhead()
    pty_round_trip()
    live_detect_shift()
    cli_search_over_pty()
    search_host_overhead()
