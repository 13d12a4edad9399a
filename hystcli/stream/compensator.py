"""Streaming compensation: the model's inverse chain one reference sample at a time, for a
robot's own control loop (docs/design.md section 9, ``hystcli.Compensator``).

:class:`Compensator` runs the same chain as ``hyst compensate`` (:func:`hystcli.core.effects.inverse`):
the inverse stages of the model's effects from the sensor back to the input, with the hysteresis
inverse of docs/design.md section 3 in the middle, each stage keeping its own state between samples
(:meth:`hystcli.core.effects.EffectType.stepper`). Fed the samples of a reference file one by one it
returns the commands ``hyst compensate`` writes for that file (to float rounding: ``exp`` and
``atanh`` may differ from the compiled kernels' by an ulp).

What is causal, and what is not:

* the hysteresis inverse, ``rate`` (inverse lags, the knob's lead limited to ``max_lead``),
  ``creep``, ``saturation``, ``contact`` and the condition effects (``friction``, ``deadzone``,
  ``stretch``: fixed for a shape/condition) are causal: sample ``i``'s command needs samples
  ``<= i`` only;
* ``coupling`` reads the other knob's command of the same sample: solved per sample by the same
  fixed-point iteration the batch inverse runs over the whole run (so a two-knob step costs up to
  ``iterations`` passes over the coupled stages: one compiled call of
  :mod:`hystcli.stream.kernels` where every coupled stage has an op there, else Python passes);
* ``latency`` (the tracker reports the tip ``delay`` s late) has no causal exact inverse: to make
  the *reported* tip follow ``r`` the command at ``t`` must aim at ``r(t + delay)``. The default
  (``latency="delay"``) buffers ``lookahead = ceil(delay / dt)`` samples: :meth:`Compensator.step`
  then returns the command of the sample ``lookahead`` steps back (the first ``lookahead`` calls
  return the knob's rest command) and :meth:`Compensator.flush` returns the last ones; these are
  exactly the commands ``hyst compensate`` writes. A caller that knows its reference ahead (a
  planned trajectory) feeds it ``lookahead`` samples early and loses nothing; a caller that does
  not gets its commands that much late. ``latency="ignore"`` leaves the delay in (no lookahead):
  the physical tip follows ``r`` and only the tracker's report lags, by ``delay``.

Time: the time-driven stages (``rate``, ``creep``, ``latency``) need each sample's time: pass
``t`` to :meth:`Compensator.step`, or give the sample period ``dt`` once (sample ``i`` is then at
``i * dt``).

A motor's limits: given ``limits``, every command goes out through a
:class:`hystcli.safety.RateLimiter` per knob, causally: the inverse's jumps (across the dead zone,
across the backlash at a reversal) are crossed at the speed (acceleration) limit and the knob
catches up with the exact commands after them (:attr:`Compensator.catch_ups` says how long it
lagged). The chain itself keeps following the exact commands: the limiter is the last stage, so
the knob lands on exactly what ``hyst compensate --allow-fast`` writes once it has caught up (a
coupling reads the other knob's exact command, not the lagging one).

Cost: a step is plain Python floats (no numpy, no numba dispatch, no allocation but the returned
float or pair), but for a coupling's fixed point, which is one numba call over preallocated arrays
(the kernel compiles, or loads from numba's cache, on the first coupled step, never at import);
:meth:`Compensator.steps` runs a knob without effects through the compiled kernel of
:mod:`hystcli.core.kernel`. The stages themselves are :mod:`hystcli.stream.stages`'.
``bench/bench_stream.py`` measures both (docs/streaming.md).
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

from ..core import kernel as core_kernel
from ..core.effects import chain
from ..core.effects.registry import as_effects
from ..core.model import Model
from ..core.params import Shape
from ..errors import DataError, ModelError
from ..safety import CatchUp, Limits, RateLimiter
from .stages import _Bend, _CompiledCoupling, _Hysteresis, _Knob

LATENCY_MODES = ("delay", "ignore")
"""What a :class:`Compensator` does with a ``latency`` effect (see the module's notes)."""


class Compensator:
    """Streaming compensation: one desired tip angle in, one knob command out, causal.

    Parameters
    ----------
    model : Model
        The catheter's model with its effects; each knob's ``offset`` is the shift in effect
        (``Model.with_offsets``, or a model ``hyst detect-shift`` wrote).
    knobs : sequence of int, optional
        Knobs to compensate (default: every knob of the model). With one knob :meth:`step`
        takes and returns floats, with two it takes and returns pairs ``(knob 1, knob 2)``.
    dt : float, optional
        Sample period (s): sample ``i`` is at ``i * dt`` when :meth:`step` gets no ``t``.
        Needed with ``latency="delay"`` (the lookahead in samples).
    shape : Shape or str, optional
        The shaft's shape, the condition of ``friction``/``deadzone`` (default: straight).
    condition : float, optional
        A stated load in place of the shape's curvature (``stretch``; docs/design.md section 6).
    latency : {"delay", "ignore"}
        With a ``latency`` effect: return exact commands ``lookahead`` samples late, or leave the
        tracker's delay uncompensated (module notes).
    max_lead : float
        Largest lead (deg) of a command over the lagged signal it aims at (``rate``), as
        ``hyst compensate``.
    iterations : int
        Most fixed-point passes per sample for ``coupling`` (two knobs).
    limits : hystcli.safety.Limits, optional
        Rate-limit every command to these speed and acceleration limits (module notes); the
        travel limit is the caller's to check. Needs each sample's time (``t`` or ``dt``).

    Raises
    ------
    ModelError
        An unknown knob, an invalid effect, an effect without a one-sample inverse, a latency
        mode that is not one of :data:`LATENCY_MODES`, or ``latency="delay"`` without ``dt``.

    Examples
    --------
    >>> import hystcli
    >>> m = hystcli.Model({1: hystcli.KnobModel(d_pos=5.0, d_neg=-5.0, b_pos=6.0, b_neg=6.0)})
    >>> c = hystcli.Compensator(m, dt=0.01)
    >>> q = [c.step(r) for r in (0.0, 2.0, 3.0, 2.5)]  # in a robot's loop: robot.move(1, c.step(r))
    >>> [round(x, 3) for x in q]
    [0.0, 6.379, 7.069, 0.724]
    >>> [round(float(y), 9) for y in m.knob(1).forward(q)]  # the model follows the reference
    [0.0, 2.0, 3.0, 2.5]
    """

    def __init__(self, model: Model, knobs: Sequence[int] | None = None, *, dt: float | None = None,
                 shape: Shape | str | None = None, condition: float | None = None,
                 latency: str = "delay", max_lead: float = 30.0, iterations: int = 50,
                 limits: Limits | None = None) -> None:
        self._model = model
        self._knobs = tuple(int(k) for k in (model.knobs if knobs is None else knobs))
        if not self._knobs or len(set(self._knobs)) != len(self._knobs):
            raise ModelError(f"a compensator needs distinct knobs, got {self._knobs}")
        for k in self._knobs:
            model.knob(k)
        model.require_loop(self._knobs, "compensate")
        if latency not in LATENCY_MODES:
            raise ModelError(f"latency must be one of {', '.join(LATENCY_MODES)}, got {latency!r}")
        if dt is not None and not (math.isfinite(dt) and dt > 0):
            raise ModelError(f"the sample period dt must be a positive number of seconds, got {dt!r}")
        self.dt = None if dt is None else float(dt)
        self.shape = shape if isinstance(shape, Shape) else Shape.parse(shape)
        self.condition = None if condition is None else float(condition)
        self.latency = latency
        self.iterations = max(int(iterations), 1)
        self._effects = as_effects(model.effects)
        self._plan = chain.Plan.of(self._effects)
        self._warnings: list[str] = []
        opts = {"max_lead": float(max_lead)}
        two = len(self._knobs) == 2
        names = {(e.name, e.form) for e in self._effects}
        if two and any(n == "coupling" for n, _ in names) and ("rate", "input2") in names:
            # measured: on the two-knob sample reference the commands of both the stream and the
            # batch inverse miss the reference by 2-5 deg RMS on the model itself (the batch says
            # its iteration did not converge); a causal step cannot check that, so it says so here
            self._warnings.append("a coupling together with a second-order input lag: the commands "
                                  "can miss the reference by degrees (the batch inverse does not "
                                  "converge either); check them with `hyst predict`")

        # the reverse steps of the batch inverse (chain._reverse_steps), minus the tracker delay,
        # which is a buffer of the reference here (it needs future samples)
        steps = chain._reverse_steps(self._plan)
        self.delay_s = 0.0
        kept = []
        for kind, e in steps:
            if kind == "sig" and e.type.preview(e) > 0.0:
                self.delay_s = max(self.delay_s, e.type.preview(e))
                continue
            kept.append((kind, e))
        cut = next((i for i, (kind, e) in enumerate(kept) if two and chain._needs_other(kind, e, self._plan)),
                   len(kept))
        # the other knob as the cross-talk sees it: through the input lags before the first stage
        # that reads the other knob (chain.inverse's `seen`), then, for a coupling driven by the
        # bend's size, through the knob's base model forward (chain.other_bend)
        bend = two and chain.reads_bend(self._plan)
        pre = []
        for e in self._plan.input:
            if e.type.cross_knob(e):
                break
            pre.append(e)
        self._chains: dict[int, _Knob] = {}
        for k in self._knobs:
            hyst = _Hysteresis(model.knob(k), k, [e for e in self._plan.edges if e.type.cross_knob(e)],
                               self._plan.output, sum(e.type.widening(e) for e in self._plan.edges),
                               opts["max_lead"], self._warnings)
            made = []
            for kind, e in kept:
                if kind == "hyst":
                    made.append(hyst)
                    continue
                s = e.type.stepper(e, k, opts, self._warnings)
                if s is None:
                    raise ModelError(f"effect {e.label()} has no one-sample inverse: the streaming "
                                     "compensator cannot run it (use `hyst compensate` on a whole file)")
                made.append(s)
            seen = []
            if two and cut < len(kept):
                for e in pre:
                    fs = getattr(e.type, "forward_stepper", None)
                    if fs is None:
                        raise ModelError(f"effect {e.label()} has no one-sample forward stage: the "
                                         "streaming compensator cannot run it with a coupling")
                    seen.append(fs(e))
                if bend:
                    seen.append(_Bend(model.knob(k)))
            self._chains[k] = _Knob(k, made[:cut], made[cut:], hyst, seen)
        self._coupled = two and cut < len(kept)
        # the coupled tails' per-sample fixed point as one compiled call, where every stage has an
        # op (hystcli/stream/kernels.py); else the Python passes of _command
        self._fast = _CompiledCoupling.build(self._chains[self._knobs[0]], self._chains[self._knobs[1]],
                                             self._plan) if self._coupled else None
        # the time-driven stages (lags, creep, the tracker delay) need each sample's time
        self._needs_t = any(e.type.driver in ("speed", "time") for e in self._effects if not e.is_null)
        self._limiters = None if limits is None else tuple(
            RateLimiter(k, limits.max_speed, limits.max_accel) for k in self._knobs)
        self._needs_t = self._needs_t or self._limiters is not None
        if self.delay_s > 0.0 and latency == "delay":
            if self.dt is None:
                raise ModelError(f"the model's latency ({self.delay_s:g} s) needs the sample period dt "
                                 "to buffer the reference (or latency='ignore')")
            ratio = self.delay_s / self.dt
            # ceil, but a ratio within rounding of an integer is that integer
            self.lookahead = int(round(ratio)) if abs(ratio - round(ratio)) < 1e-9 else int(math.ceil(ratio))
        else:
            self.lookahead = 0
        n = self.lookahead + 1
        self._buf_t = [0.0] * n
        self._buf_r = [[0.0] * n for _ in self._knobs]
        self._refresh()
        self.reset()

    # -- construction helpers --------------------------------------------------------------------
    @classmethod
    def for_run(cls, model: Model, meta: Mapping[str, str], knobs: Sequence[int] | None = None,
                offsets: Mapping[int, float] | None = None, **kwargs: Any) -> "Compensator":
        """The compensator ``hyst compensate`` would use for a reference with metadata ``meta``:
        each knob's offset by docs/design.md section 6's rule (:meth:`Model.offsets_for`) unless
        ``offsets`` are given, the shape and the stated condition from ``meta``."""
        offs = model.offsets_for(meta) if offsets is None else dict(offsets)
        return cls(model.with_offsets(offs), knobs, shape=Shape.parse(meta.get("shape")),
                   condition=chain.run_condition(meta, "reference"), **kwargs)

    # -- state -------------------------------------------------------------------------------------
    @property
    def knobs(self) -> tuple[int, ...]:
        """The knobs compensated, in the order :meth:`step` takes and returns them."""
        return self._knobs

    @property
    def model(self) -> Model:
        """The model with the offsets in effect now."""
        return self._model

    @property
    def offsets(self) -> dict[int, float]:
        """The offset (shift) of every knob of the model now (deg)."""
        return {k: kn.offset for k, kn in self._model.knobs.items()}

    @property
    def warnings(self) -> tuple[str, ...]:
        """What the inverse warned about so far (a target beyond a wall or a saturation), once each."""
        return tuple(dict.fromkeys(self._warnings))

    @property
    def catch_ups(self) -> dict[int, CatchUp]:
        """Per knob whose commands the ``limits`` held back so far, how long it lagged the exact
        commands (:class:`hystcli.safety.CatchUp`); empty without ``limits`` or when none was."""
        out = {}
        for lim in self._limiters or ():
            c = lim.catch_up()
            if c is not None:
                out[lim.knob] = c
        return out

    @property
    def rest_command(self) -> tuple[float, ...]:
        """Per knob, the command while the reference rests at the tip reading it started from (the
        middle of the knob range that holds it): what :meth:`step` returns while the latency
        buffer fills."""
        return tuple(self._chains[k].hyst.kn.holding_knob_angle(self._rest_y[i])
                     for i, k in enumerate(self._knobs))

    def reset(self, y0: float | Sequence[float] = 0.0) -> None:
        """Start again: the tip reads ``y0`` (deg; a pair for two knobs) at rest, every lag at rest,
        the latency buffer empty, the clock at 0. ``hyst compensate`` starts from 0."""
        ys = self._per_knob(y0, "y0", broadcast=True)
        self._rest_y = ys
        for i, k in enumerate(self._knobs):
            self._chains[k].reset(ys[i])
        if self._fast is not None:
            self._fast.reset()
        for lim in self._limiters or ():
            lim.reset()
        self._n = 0          # samples taken
        self._last_t = -math.inf
        self._filled = 0     # samples in the latency buffer
        self._rest = self.rest_command

    def set_offset(self, k: int, offset: float) -> None:
        """Set knob ``k``'s offset (absolute, deg) between two steps, e.g. after a new Algorithm 1
        result (``Model.with_offsets``). The chain's state (where the tip is, the lags) is kept:
        the next command follows the shifted loop from the present tip."""
        offset = float(offset)
        if not math.isfinite(offset):
            raise ModelError(f"offset of knob {k} must be finite, got {offset!r}")
        self._model.knob(k)
        self._model = self._model.with_offsets({int(k): offset})
        self._refresh()

    def rotate(self, delta_deg: float) -> None:
        """A bulk rotation of the catheter body by ``delta_deg`` (deg) between two steps: rotates
        the offsets' vector by ``-delta_deg`` (``Model.rotated``, docs/design.md section 3)."""
        delta = float(delta_deg)
        if not math.isfinite(delta):
            raise ModelError(f"rotation must be finite, got {delta_deg!r}")
        self._model = self._model.rotated(delta)
        self._refresh()

    def _refresh(self) -> None:
        # the knob parameters under the shape/condition with the offsets now
        for k, ch in self._chains.items():
            kn = chain.condition_knob(self._model.knob(k), self._plan, self.shape, self.condition, k=k)
            ch.hyst.set_knob(kn)
            # this knob's bend (what the other knob's magnitude coupling reads): its base model,
            # not conditioned, with its offset now (chain.inverse's `bases`)
            for s in ch.seen:
                if isinstance(s, _Bend):
                    s.kn = self._model.knob(k)
        if self._fast is not None:
            self._fast.load_params()

    def _per_knob(self, value: Any, what: str, broadcast: bool = False) -> list[float]:
        n = len(self._knobs)
        if (n == 1 or broadcast) and not isinstance(value, (tuple, list, np.ndarray)):
            return [float(value)] * n
        vals = [float(v) for v in (value if isinstance(value, (tuple, list, np.ndarray)) else (value,))]
        if len(vals) != n:
            raise DataError(f"{what}: expected {n} value{'s' if n > 1 else ''} (knobs "
                            f"{', '.join(map(str, self._knobs))}), got {len(vals)}")
        return vals

    # -- the stream ---------------------------------------------------------------------------------
    def _time(self, t: float | None) -> float:
        if t is None:
            if self.dt is None:
                if self._needs_t:
                    raise DataError(f"sample {self._n}: the model's time-driven effects and the rate "
                                    "limit need the sample's time t (or a sample period dt)")
                return float(self._n)  # read by no stage
            return self._n * self.dt
        t = float(t)
        if not t > self._last_t:  # also refuses NaN
            raise DataError(f"sample {self._n}: time {t!r} must be after the previous sample's "
                            f"({self._last_t!r})")
        return t

    def _command(self, rs: list[float], t: float) -> tuple[float, ...]:
        # one sample (after the latency buffer) through every knob's chain, then the rate limit
        q = self._exact(rs, t)
        if self._limiters is None:
            return q
        return tuple(lim.step(v, t) for lim, v in zip(self._limiters, q))

    def _exact(self, rs: list[float], t: float) -> tuple[float, ...]:
        if not self._coupled:
            return tuple(self._chains[k].run(rs[i], t, None) for i, k in enumerate(self._knobs))
        c1, c2 = self._chains[self._knobs[0]], self._chains[self._knobs[1]]
        fast = self._fast
        if fast is not None:
            h1 = rs[0]
            for s in c1.head:
                h1 = s.step(h1, t, None)
            h2 = rs[1]
            for s in c2.head:
                h2 = s.step(h2, t, None)
            if fast.pending:
                fast.start()
            q1, q2, ok = fast.kernel(h1, h2, t, self.iterations, fast.ops, fast.rng, fast.par, fast.st, fast.work)
            if not ok:
                self._warnings.append("the coupling's per-sample fixed point did not converge: the last "
                                      "iterate is used")
            return (q1, q2)
        # the head (stages that read no other knob) once; then the tail solved for both knobs by
        # the batch inverse's fixed-point iteration, restarted from this sample's state each pass
        h1 = h2 = 0.0
        for i, ch in enumerate((c1, c2)):
            z = rs[i]
            for s in ch.head:
                z = s.step(z, t, None)
            if i == 0:
                h1 = z
            else:
                h2 = z
        s1, s2 = c1.save_tail(), c2.save_tail()
        seen1 = tuple(s.save() for s in c1.seen)
        seen2 = tuple(s.save() for s in c2.seen)

        def tail(ch, state, h, other):
            ch.load_tail(state)
            for s in ch.tail:
                h = s.step(h, t, other)
            return h

        def see(ch, state, q):
            for s, v in zip(ch.seen, state):
                s.load(v)
            for s in ch.seen:
                q = s.step(q, t)
            return q

        q1 = tail(c1, s1, h1, None)
        q2 = tail(c2, s2, h2, None)
        for _ in range(self.iterations):
            n1 = tail(c1, s1, h1, see(c2, seen2, q2))
            n2 = tail(c2, s2, h2, see(c1, seen1, q1))
            change = max(abs(n1 - q1), abs(n2 - q2))
            q1, q2 = n1, n2
            if change < 1e-10:
                break
        else:
            self._warnings.append("the coupling's per-sample fixed point did not converge: the last "
                                  "iterate is used")
        # commit what the other knob's coupling saw of each command this sample
        see(c1, seen1, q1)
        see(c2, seen2, q2)
        return (q1, q2)

    def step(self, r: float | Sequence[float], t: float | None = None) -> float | tuple[float, float]:
        """One reference sample in, one command out.

        Parameters
        ----------
        r : float or pair of float
            Desired tip angle(s) (deg), one per knob of :attr:`knobs`.
        t : float, optional
            The sample's time (s), increasing; default ``i * dt``.

        Returns
        -------
        float or tuple of float
            The knob command(s) (deg). With a ``lookahead`` (latency), the command of the sample
            ``lookahead`` steps back (the rest command until the buffer holds that many).

        Raises
        ------
        DataError
            A non-finite reference, a time not after the previous one, the wrong number of values.
        """
        if len(self._knobs) == 1 and not self.lookahead and not isinstance(r, (tuple, list, np.ndarray)):
            # the hot path of one knob: no list, no tuple
            r = float(r)
            if not math.isfinite(r):
                raise DataError(f"sample {self._n}: reference {r!r} is not a finite number")
            tt = self._time(t)
            self._last_t = tt
            self._n += 1
            q = self._chains[self._knobs[0]].run(r, tt, None)
            return q if self._limiters is None else self._limiters[0].step(q, tt)
        rs = self._per_knob(r, f"sample {self._n}")
        for v in rs:
            if not math.isfinite(v):
                raise DataError(f"sample {self._n}: reference {v!r} is not a finite number")
        tt = self._time(t)
        self._last_t = tt
        self._n += 1
        if self.lookahead:
            out = self._push(tt, rs)
            if out is None:
                q = self._rest
            else:
                q = self._command(*out)
        else:
            q = self._command(rs, tt)
        return q[0] if len(q) == 1 else q

    # the latency buffer: the last lookahead + 1 samples, a ring
    def _push(self, t: float, rs: list[float]) -> tuple[list[float], float] | None:
        n = self.lookahead + 1
        j = (self._n - 1) % n
        self._buf_t[j] = t
        for i, v in enumerate(rs):
            self._buf_r[i][j] = v
        self._filled += 1
        if self._filled <= self.lookahead:
            return None
        return self._aim(self._n - 1 - self.lookahead, self._n - 1)

    def _aim(self, i: int, last: int) -> tuple[list[float], float]:
        # the reference at t_i + delay by linear interpolation over the buffered samples i..last
        # (np.interp's formula), held at the last one beyond it
        n = self.lookahead + 1
        ti = self._buf_t[i % n]
        x = ti + self.delay_s
        out = []
        for buf in self._buf_r:
            value = buf[last % n]
            for j in range(i, last):
                a, b = self._buf_t[j % n], self._buf_t[(j + 1) % n]
                if a <= x < b:
                    fa, fb = buf[j % n], buf[(j + 1) % n]
                    value = (fb - fa) / (b - a) * (x - a) + fa if x != a else fa
                    break
            out.append(value)
        return out, ti

    def flush(self) -> list:
        """The commands still in the latency buffer (the reference held at its last sample, as
        ``hyst compensate`` holds it at the end of a file): call once after the last :meth:`step`.
        Empty without a lookahead. Each item as :meth:`step` returns it."""
        if not self.lookahead or self._filled == 0:
            return []
        last = self._n - 1
        first = max(self._n - self.lookahead, 0)
        out = []
        for i in range(first, self._n):
            rs, ti = self._aim(i, last)
            q = self._command(rs, ti)
            out.append(q[0] if len(q) == 1 else q)
        self._filled = 0
        return out

    def steps(self, r: Any, t: Any = None) -> np.ndarray:
        """A block of samples: the same as :meth:`step` in a loop, as one array.

        Parameters
        ----------
        r : array_like, shape (n,) or (n, 2)
            Desired tip angles, one column per knob of :attr:`knobs`.
        t : array_like, shape (n,), optional
            Sample times (default ``i * dt``).

        Returns
        -------
        numpy.ndarray
            Commands of the same shape (with a lookahead, shifted as :meth:`step` shifts them).
        """
        rr = np.asarray(r, dtype=np.float64)
        nk = len(self._knobs)
        if (nk == 1 and rr.ndim != 1) or (nk == 2 and (rr.ndim != 2 or rr.shape[1] != 2)):
            raise DataError(f"steps expects shape (n,) for one knob or (n, 2) for two, got {rr.shape}")
        tt = None if t is None else np.asarray(t, dtype=np.float64)
        if tt is not None and tt.shape != (rr.shape[0],):
            raise DataError(f"steps: t has shape {tt.shape}, r has {rr.shape[0]} samples")
        if nk == 1 and not self.lookahead and rr.size:
            ch = self._chains[self._knobs[0]]
            timed = tt is not None or self.dt is not None or self._limiters is None
            if not ch.tail and ch.head == [ch.hyst] and ch.hyst.plain and timed and np.all(np.isfinite(rr)):
                # the compiled kernel of hystcli.core.kernel: the same operations, so the same numbers
                if tt is not None:
                    self._check_times(tt)
                h = ch.hyst
                if h.fresh:
                    h._start(None)
                out = np.empty_like(rr)
                h.y = float(core_kernel.inverse(np.ascontiguousarray(rr), *h.kn._kernel_args(), h.y, h.x, out))
                h.x = float(out[-1])
                first = self._n
                self._n += rr.size
                self._last_t = float(tt[-1]) if tt is not None else (
                    (self._n - 1) * self.dt if self.dt is not None else float(self._n - 1))
                if self._limiters is not None:
                    times = tt if tt is not None else (first + np.arange(rr.size)) * self.dt
                    step = self._limiters[0].step
                    out = np.array([step(q, ti) for q, ti in zip(out.tolist(), times.tolist())])
                return out
        out = np.empty_like(rr)
        step = self.step
        if nk == 1:
            for i in range(rr.shape[0]):
                out[i] = step(rr[i], None if tt is None else tt[i])
        else:
            for i in range(rr.shape[0]):
                out[i] = step((rr[i, 0], rr[i, 1]), None if tt is None else tt[i])
        return out

    def _check_times(self, tt: np.ndarray) -> None:
        if not np.all(np.isfinite(tt)) or (tt.size > 1 and np.any(np.diff(tt) <= 0)) or not tt[0] > self._last_t:
            raise DataError("steps: t must be finite and strictly increasing, after the previous sample")


__all__ = ["Compensator", "LATENCY_MODES"]
