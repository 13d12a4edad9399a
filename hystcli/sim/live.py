"""The live twin: the virtual catheter stepped move by move, as a robot is (what `hyst sim-robot`
serves)."""
from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np
from scipy import signal

from ..core.effects import ChainState, Effect, as_effects, format_effects
from ..core.params import EffectSpec, Shape
from ..core.run import Run
from ..errors import DataError, ModelError
from ..filters import butter_sos
from .twin import CurrentState, VirtualCatheter, _knob_signals


class LiveTwin:
    """The virtual catheter stepped move by move, as a robot would be (for the serial emulator).

    Every knob advances on one shared clock: while one knob moves, the others hold their angle
    (and their effects, like creep, go on in time). The hysteresis, play, lag, tracker and filter
    states are carried between moves, so the samples of a sequence of moves are those of one
    batch :func:`simulate` of the concatenated motion (noise aside).

    Parameters
    ----------
    catheter : VirtualCatheter
    shape : Shape
        Shaft shape (change it with :meth:`set_shape`).
    rotation : float
        Bulk rotation of the catheter body (deg).
    effects : sequence of Effect or EffectSpec
        Unmodelled effects; ``()`` none, ``None`` the catheter's defaults.
    seed : int
        Seed of the current and EM noise.
    knobs : tuple of int
        The knobs the robot has.
    noise : bool
        Add current noise (before the filter) and EM noise (on the tip reading).
    tip_available : bool
        Whether an EM tracker is fitted; without one the tip reading is NaN.
    filter_hz : float or None
        Cut-off of the causal Butterworth filter on the current (the paper's 20 Hz).
    record : bool
        Keep every sample (:meth:`recorded`), noise-free current before the filter included.
    """

    def __init__(self, catheter: VirtualCatheter, shape: Shape = Shape(), rotation: float = 0.0,
                 effects: Sequence[Effect | EffectSpec] | None = (), seed: int = 0,
                 knobs: Sequence[int] = (1, 2), *, noise: bool = True, tip_available: bool = True,
                 filter_hz: float | None = 20.0, record: bool = False) -> None:
        self.catheter = catheter
        self.knobs = tuple(int(k) for k in knobs)
        if not self.knobs:
            raise ModelError("a live twin needs at least one knob")
        for k in self.knobs:
            if k not in catheter.knobs:
                raise ModelError(f"virtual catheter {catheter.name} has no knob {k!r}")
        self.effects = as_effects(catheter.default_effects if effects is None else effects)
        self.noise = bool(noise)
        self.tip_available = bool(tip_available)
        self.filter_hz = filter_hz
        # separate streams: reading the tip (or not) must not change the current's noise
        cur_seq, em_seq = np.random.SeedSequence(int(seed)).spawn(2)
        self._rng_current = np.random.default_rng(cur_seq)
        self._rng_em = np.random.default_rng(em_seq)
        self.t = 0.0
        self._started = False
        self._last: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._q = {k: 0.0 for k in self.knobs}
        self._c = {k: catheter.current.no_load for k in self.knobs}
        self._y = {k: 0.0 for k in self.knobs}
        self._chain = {k: ChainState() for k in self.knobs}
        self._cur = {k: CurrentState() for k in self.knobs}
        self._zi: dict[int, np.ndarray] = {}
        self._sos_dt: float | None = None
        self._sos = None
        self._record = bool(record)
        self._log: list[dict[str, np.ndarray]] = []
        self.set_shape(shape, rotation)

    # -- configuration --------------------------------------------------------------------------
    def set_shape(self, shape: Shape, rotation: float = 0.0) -> None:
        """Bend the shaft into ``shape`` (the knobs' states are kept: the shift moves under them)."""
        self.shape = shape
        self.rotation = float(rotation)
        offs = self.catheter.true_offsets(shape, rotation)
        self.true_offsets = {k: offs[k] for k in self.knobs}
        self._models = {k: self.catheter.knobs[k].with_offset(offs[k]) for k in self.knobs}

    def _check_knob(self, knob: int) -> int:
        try:
            k = int(knob)
        except (TypeError, ValueError):
            raise DataError(f"bad knob {knob!r}") from None
        if k not in self.knobs:
            raise DataError(f"no knob {knob!r} (knobs: {', '.join(map(str, self.knobs))})")
        return k

    # -- motion ---------------------------------------------------------------------------------
    def move(self, knob: int, q_target: float, speed_deg_s: float = 20.0,
             dt: float = 0.001) -> tuple[float, float, float]:
        """Turn ``knob`` to ``q_target`` at constant speed, sampling every ``dt`` seconds.

        Returns
        -------
        tuple of float
            ``(knob angle, filtered motor current at the last sample (still moving), tip
            angle read by the EM tracker)``; the tip is NaN without a tracker.
        """
        k = self._check_knob(knob)
        q_target = float(q_target)
        if not math.isfinite(q_target):
            raise DataError(f"knob {k} target must be finite, got {q_target}")
        if not (speed_deg_s > 0 and math.isfinite(speed_deg_s)):
            raise DataError(f"speed must be positive, got {speed_deg_s}")
        if not (dt > 0 and math.isfinite(dt)):
            raise DataError(f"sample interval dt must be positive, got {dt}")
        q0 = self._q[k]
        n = max(1, int(math.ceil(abs(q_target - q0) / (speed_deg_s * dt) - 1e-9)))
        steps = np.arange(1, n + 1)
        qk = q0 + (q_target - q0) * (steps / n)
        qk[-1] = q_target
        t = self.t + dt * steps
        if not self._started:
            # the robot's first sample: the knobs at rest where they start
            qk = np.concatenate([[q0], qk])
            t = np.concatenate([[self.t], t])
            self._started = True
        qs = {j: (qk if j == k else np.full(t.shape, self._q[j])) for j in self.knobs}
        self._advance(t, qs, dt, n)
        return self.state(k)

    def hold(self, duration: float, dt: float = 0.001) -> None:
        """Let ``duration`` seconds pass with every knob still (creep and the tracker go on)."""
        n = max(1, int(round(duration / dt)))
        t = self.t + dt * np.arange(1, n + 1)
        if not self._started:
            t = np.concatenate([[self.t], t])
            self._started = True
        self._advance(t, {j: np.full(t.shape, self._q[j]) for j in self.knobs}, dt, n)

    def _advance(self, t: np.ndarray, qs: Mapping[int, np.ndarray], dt: float, n: int) -> None:
        # n: the samples this move or hold took (t may start with the robot's first sample at rest)
        ys, cs = _knob_signals(self.catheter, self._models, qs, t, self.effects, self.shape,
                               self._chain, self._cur)
        if self._sos_dt != dt and self.filter_hz is not None:
            self._sos = butter_sos(1.0 / dt, self.filter_hz)
            self._sos_dt = dt
        for k in self.knobs:
            c = cs[k]
            if self.noise:
                c = c + self._rng_current.normal(0.0, self.catheter.current.noise, c.shape)
            if self.filter_hz is not None:
                if k not in self._zi or self._zi[k].shape[0] != self._sos.shape[0]:
                    self._zi[k] = signal.sosfilt_zi(self._sos) * c[0]
                cf, self._zi[k] = signal.sosfilt(self._sos, c, zi=self._zi[k])
            else:
                cf = c
            self._last[k] = (np.asarray(qs[k][-n:], dtype=float), cf[-n:])
            self._q[k] = float(qs[k][-1])
            self._c[k] = float(cf[-1])
            self._y[k] = float(ys[k][-1])
            if self._record:
                self._log.append({"k": k, "t": t, "q": qs[k], "y": ys[k], "c_raw": cs[k], "c": cf})
        self.t = float(t[-1])

    # -- readings -------------------------------------------------------------------------------
    def state(self, knob: int) -> tuple[float, float, float]:
        """``(knob angle, filtered motor current, tip angle read now)`` without moving."""
        k = self._check_knob(knob)
        if not self.tip_available:
            tip = math.nan
        elif self.noise:
            tip = self._y[k] + float(self._rng_em.normal(0.0, self.catheter.em_noise_deg))
        else:
            tip = self._y[k]
        return self._q[k], self._c[k], tip

    def last_samples(self, knob: int) -> tuple[np.ndarray, np.ndarray]:
        """``(knob angles, filtered motor currents)`` of every sample of the last move or hold
        (what a controller sampling at ``dt`` saw; empty before the first one)."""
        k = self._check_knob(knob)
        return self._last.get(k, (np.empty(0), np.empty(0)))

    def recorded(self) -> Run:
        """Every sample so far (needs ``record=True``): ``t``, ``q<k>``, ``y<k>`` (noise-free
        tip), ``c<k>`` (noise-free current before the filter), ``cf<k>`` (filtered current)."""
        if not self._record:
            raise DataError("this live twin was made without record=True")
        cols: dict[str, list] = {}
        ts = [e["t"] for e in self._log if e["k"] == self.knobs[0]]
        cols["t"] = np.concatenate(ts) if ts else np.empty(0)
        for k in self.knobs:
            for name, key in (("q", "q"), ("y", "y"), ("c", "c_raw"), ("cf", "c")):
                parts = [e[key] for e in self._log if e["k"] == k]
                cols[f"{name}{k}"] = np.concatenate(parts) if parts else np.empty(0)
        meta = {"catheter": self.catheter.name, "shape": str(self.shape),
                "effects": format_effects(self.effects)}
        return Run(cols, meta, "live twin")
