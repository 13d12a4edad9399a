"""The virtual catheter: a seeded simulator of the physical system the paper measured.

It owns the true parameters of named virtual catheters, the motions of the paper's protocol
(sweep, periodic, non-periodic), the motor-current model of docs/design.md section 4, the sensor chain
(EM-tracker noise, 20 Hz Butterworth) and two ways to run it: :func:`simulate` (a whole run at
once; the demo, the tests, the sample data, ``hyst simulate`` through :func:`simulate_motion`)
and :class:`LiveTwin` (move by move, for the serial emulator), which carry the same states and
so give the same samples. The tip angle comes from :mod:`hystcli.core.effects` (the base model of
docs/design.md section 3 plus the unmodelled effects of section 8); this module adds the current.

Motor current (signed, mA), for the tendon input ``u`` (the knob angle seen through the coupling
and rate effects) relative to the shifted edges::

    L_pos, L_neg = the taut tendon's load (deg of knob), from the knob's own hysteresis state y:
                   pulling the tip up past its rising plateau,   L_pos = (y - h_pos) / omega;
                   holding it after a reversal (the tip rests on its backlash plateau, the sheath
                   friction holds the tendon), L_pos stays where it was;
                   letting it down, L_pos falls linearly in y to 0 where the tip settles on its
                   falling plateau h_neg (the negative tendon mirrored)
    T      = k_load * (L_pos - L_neg)                        tendon tension
    phi    = the sheath friction's sign, flipping over ``flip`` deg of knob after a reversal
    c      = c_no_load + c_coulomb * tanh(dq/dt / v_s) + T + mu * |T| * phi + contact + noise

So the current is flat in the dead zone (no tendon taut), rises with slope ``k_load (1 + mu)``
once a tendon is taut, and after a reversal drops by ``2 mu |T|`` at once (the sheath friction
changes sign), stays level while the knob crosses the backlash and the tip rests on its plateau,
then unloads as the tip comes down (the current's signature of the backlash). Contact with a wall
adds ``stiffness`` mA per degree of knob past it (the ``contact`` effect). The motor velocity
``dq/dt`` is a backward difference, so the live twin can compute it causally.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Mapping, Sequence

import numpy as np
from numba import njit

from ..core import kernel
from ..core.effects import ChainState, Effect, as_effects, contact_current, format_effects, tip_chain
from ..core.model import Model
from ..core.params import EffectSpec, Geometry, KnobModel, Shape
from ..core.run import Run
from ..errors import DataError, ModelError
from ..filters import lowpass
from ..names import MOTIONS  # the motions simulate_motion generates (named where `--help` reads them)


@dataclass(frozen=True)
class CurrentParams:
    """Motor-current model of one knob (see the module docstring).

    Attributes
    ----------
    no_load : float
        Current with no tendon taut and the motor still (mA).
    coulomb : float
        Motor and gearbox Coulomb friction (mA), signed by the knob velocity.
    v_smooth : float
        Velocity (deg/s) over which the Coulomb term changes sign.
    k_load : float
        Current per degree of knob past the slack edge (mA/deg).
    mu : float
        Sheath friction ratio: the loading slope is ``k_load (1 + mu)``; at a reversal the current
        drops by ``2 mu |T|``.
    flip : float
        Knob travel (deg) over which the sheath friction changes sign after a reversal.
    noise : float
        White current noise before the 20 Hz filter (mA rms).
    """

    no_load: float = 120.0
    coulomb: float = 6.0
    v_smooth: float = 0.5
    k_load: float = 4.0
    mu: float = 0.25
    flip: float = 0.5
    noise: float = 3.0


@dataclass(frozen=True)
class VirtualCatheter:
    """A named virtual catheter: its true straight-shaft model and its sensors.

    Attributes
    ----------
    name : str
    knobs : mapping of int to KnobModel
        True hysteresis of each knob on the straight shaft (offset 0).
    geometry : Geometry
        Tendon geometry; the shape of the shaft shifts each knob by ``geometry.offsets(shape)``.
    current : CurrentParams
    em_noise_deg : float
        EM-tracker noise on the tip angle before the 20 Hz filter (deg rms).
    default_effects : tuple of EffectSpec
        Unmodelled effects the catheter has unless told otherwise.
    """

    name: str
    knobs: Mapping[int, KnobModel]
    geometry: Geometry
    current: CurrentParams = CurrentParams()
    em_noise_deg: float = 0.3
    default_effects: tuple[EffectSpec, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "knobs", MappingProxyType(dict(self.knobs)))
        object.__setattr__(self, "default_effects", tuple(self.default_effects))

    def true_offsets(self, shape: Shape, rotation: float = 0.0) -> dict[int, float]:
        """The true shift of each knob under ``shape`` after a body rotation (deg)."""
        o1, o2 = self.geometry.offsets(shape.rotated(rotation))
        return {1: o1, 2: o2}

    def true_model(self, shape: Shape = Shape(), rotation: float = 0.0) -> Model:
        """The base model (no effects) this catheter follows under ``shape``."""
        offs = self.true_offsets(shape, rotation)
        return Model({k: kn.with_offset(offs[k]) for k, kn in self.knobs.items()}, self.geometry,
                     meta={"catheter": self.name})


# Two plain virtual catheters with docs/design.md section 6's example knob (and one like it): fixed
# reference plants for tests and benches, with no effects by default; beta_catheter / beta_knob
# from a 10 Fr shaft (tendons ~1.2 mm off axis) and an 8 mm knob pulley. The catheters users
# simulate and the sample data was recorded on, ice-a and ice-b, are the calibrated ones of
# hystcli.sim.calibration, built on these sensors and current models.
CATHETERS: Mapping[str, VirtualCatheter] = MappingProxyType({
    "example-a": VirtualCatheter(
        "example-a",
        {1: KnobModel(d_pos=9.1, d_neg=-8.7, b_pos=6.2, b_neg=5.9, omega=1.45, h_pos=-4.0, h_neg=4.2),
         2: KnobModel(d_pos=8.4, d_neg=-9.3, b_pos=5.6, b_neg=6.4, omega=1.40, h_pos=-3.6, h_neg=3.9)},
        Geometry(beta_catheter_mm=1.2, beta_knob_mm=8.0),
    ),
    "example-b": VirtualCatheter(
        "example-b",
        {1: KnobModel(d_pos=10.2, d_neg=-9.6, b_pos=6.8, b_neg=6.5, omega=1.50, h_pos=-4.5, h_neg=4.4),
         2: KnobModel(d_pos=9.8, d_neg=-10.4, b_pos=7.1, b_neg=6.6, omega=1.48, h_pos=-4.2, h_neg=4.6)},
        Geometry(beta_catheter_mm=1.3, beta_knob_mm=8.0),
        CurrentParams(no_load=135.0, coulomb=7.0, k_load=3.6, mu=0.22, noise=3.5),
    ),
})


def get_catheter(name: str) -> VirtualCatheter:
    """The virtual catheter called ``name`` (raises :class:`ModelError` naming the known ones)."""
    try:
        return CATHETERS[name]
    except KeyError:
        raise ModelError(f"unknown virtual catheter {name!r} (known: {', '.join(CATHETERS)})") from None


# --------------------------------------------------------------------------------------------
# motions of the paper's protocol (docs/design.md section 7)
# --------------------------------------------------------------------------------------------
def time_axis(duration: float, fs: float) -> np.ndarray:
    """Sample times ``0, 1/fs, ...`` covering ``duration`` seconds."""
    if not (duration > 0 and fs > 0):
        raise DataError("duration and sample rate must be positive")
    n = int(round(duration * fs)) + 1
    return np.arange(n) / fs


def sweep(amplitude: float = 40.0, cycles: float = 2.0, peak_speed: float = 40.0,
          fs: float = 1000.0) -> tuple[np.ndarray, np.ndarray]:
    """The identification sweep: a sine of ``amplitude`` deg whose peak speed is ``peak_speed``.

    The paper's sweep is +-40 deg, 2 cycles, 40 deg/s (section II-C-2). Returns ``(t, q)``.
    """
    w = peak_speed / amplitude  # rad/s
    duration = cycles * 2 * math.pi / w
    t = time_axis(duration, fs)
    return t, amplitude * np.sin(w * t)


def periodic(amplitude: float = 60.0, freq: float = 0.04, cycles: float = 2.0,
             fs: float = 100.0) -> tuple[np.ndarray, np.ndarray]:
    """The paper's periodic reference: ``amplitude`` deg at ``freq`` Hz. Returns ``(t, r)``."""
    t = time_axis(cycles / freq, fs)
    return t, amplitude * np.sin(2 * math.pi * freq * t)


def nonperiodic(amplitude: float = 30.0, freq: float = 0.02, duration: float = 100.0,
                fs: float = 100.0, speed: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The paper's non-periodic reference: two sines of ``amplitude`` at ``freq`` and ``freq*sqrt(3)``.

    ``speed`` scales time (the 2-DoF case runs one knob twice as fast). Returns ``(t, r)``.
    """
    t = time_axis(duration, fs)
    ts = speed * t
    return t, amplitude * (np.sin(2 * math.pi * freq * ts) + np.sin(2 * math.pi * freq * math.sqrt(3) * ts))


# --------------------------------------------------------------------------------------------
# the physics
# --------------------------------------------------------------------------------------------
@njit(cache=True)
def _play(u, width, phi0, prev0, out):
    # play operator normalised to [-1, 1]: moves 2/width per degree of knob travel
    phi = phi0
    prev = prev0
    for i in range(u.shape[0]):
        if width > 0:
            phi += 2.0 * (u[i] - prev) / width
            if phi > 1.0:
                phi = 1.0
            elif phi < -1.0:
                phi = -1.0
        else:
            d = u[i] - prev
            if d > 0:
                phi = 1.0
            elif d < 0:
                phi = -1.0
        prev = u[i]
        out[i] = phi
    return phi


@njit(cache=True)
def _loads(u, d_pos, d_neg, b_pos, b_neg, omega, h_pos, h_neg, st, out):
    # the tip's clamp recursion (the knob's own hysteresis state) and each tendon's load (deg of
    # stretch): taken up past its edge while the knob pulls it, held after a reversal while the
    # tip rests, let down linearly in the tip angle to 0 where the tip settles on its plateau.
    # st = (y, u_prev, L_pos, L_neg, L_pos at its reversal, y there, L_neg at its reversal, y there)
    dhat_pos = (h_pos - h_neg) / omega + d_neg + b_neg
    dhat_neg = (h_neg - h_pos) / omega + d_pos - b_pos
    y, prev, lp, ln, lp0, yp0, ln0, yn0 = st[0], st[1], st[2], st[3], st[4], st[5], st[6], st[7]
    for i in range(u.shape[0]):
        x = u[i]
        y_new = kernel.forward_step(y, x, d_pos, d_neg, dhat_pos, dhat_neg, omega, h_pos, h_neg)
        if x > prev:
            lp = max(lp, x - d_pos)
            lp0, yp0 = lp, y_new
            if ln > 0.0 and y_new > y:
                ln = ln0 * max(h_pos - y_new, 0.0) / max(h_pos - yn0, 1e-12)
        elif x < prev:
            ln = max(ln, d_neg - x)
            ln0, yn0 = ln, y_new
            if lp > 0.0 and y_new < y:
                lp = lp0 * max(y_new - h_neg, 0.0) / max(yp0 - h_neg, 1e-12)
        y = y_new
        prev = x
        out[i] = lp - ln
    st[0], st[1], st[2], st[3], st[4], st[5], st[6], st[7] = y, prev, lp, ln, lp0, yp0, ln0, yn0


@dataclass
class CurrentState:
    """What the motor-current model of one knob carries between calls (the live twin).

    Attributes
    ----------
    phi : float
        Sheath friction's sign state in [-1, 1].
    loads : numpy.ndarray or None
        The hysteresis state behind the tendons' loads (tip, loads, peaks); None: fresh.
    u_prev : float
        Last knob input relative to the shift (deg).
    q_prev, t_prev : float
        Last motor angle (deg) and time (s), for the backward-difference velocity.
    """

    phi: float = 0.0
    loads: np.ndarray | None = None
    u_prev: float | None = None
    q_prev: float | None = None
    t_prev: float | None = None


def motor_current(knob: KnobModel, cur: CurrentParams, q: np.ndarray, t: np.ndarray,
                  phi0: float = 0.0, *, x: np.ndarray | None = None,
                  state: CurrentState | None = None) -> np.ndarray:
    """Noise-free motor current (mA) of one knob for commands ``q`` at times ``t``.

    Parameters
    ----------
    knob : KnobModel
        The knob, carrying the shift in its ``offset``.
    cur : CurrentParams
    q : numpy.ndarray
        Motor (knob) angles, deg: drive the Coulomb term through their velocity.
    t : numpy.ndarray
        Sample times, s.
    phi0 : float
        Initial friction state (when ``state`` is not given).
    x : numpy.ndarray, optional
        The input the tendons see, when effects make it differ from ``q`` (coupling, rate).
    state : CurrentState, optional
        Carried between calls; updated in place.

    Notes
    -----
    The velocity is the backward difference ``(q_i - q_{i-1}) / (t_i - t_{i-1})`` (causal, so
    the live twin can compute it), the first sample of a run taking the second's. A fresh state
    starts the tip at rest on the straight shaft (y = 0 clamped into the loop), no tendon loaded.
    """
    q = np.asarray(q, float)
    u = np.ascontiguousarray((q if x is None else np.asarray(x, float)) - knob.offset)
    load = np.empty_like(u)
    phi = np.empty_like(u)
    v = np.zeros_like(q)
    t = np.asarray(t, float)
    if u.size:
        fresh = state is None or state.u_prev is None
        st = (np.array([0.0, u[0], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]) if fresh or state.loads is None
              else state.loads.copy())
        _loads(u, knob.d_pos, knob.d_neg, knob.b_pos, knob.b_neg, knob.omega, knob.h_pos, knob.h_neg, st, load)
        phi_start = phi0 if state is None else state.phi
        phi_end = _play(u, cur.flip, phi_start, u[0] if fresh else state.u_prev, phi)
        if q.size > 1:
            v[1:] = np.diff(q) / np.diff(t)
        if fresh:
            v[0] = v[1] if q.size > 1 else 0.0
        else:
            v[0] = (q[0] - state.q_prev) / (t[0] - state.t_prev)
        if state is not None:
            state.phi, state.u_prev, state.loads = float(phi_end), float(u[-1]), st
            state.q_prev, state.t_prev = float(q[-1]), float(t[-1])
    tension = cur.k_load * load
    return cur.no_load + cur.coulomb * np.tanh(v / cur.v_smooth) + tension + cur.mu * np.abs(tension) * phi


def _knob_signals(catheter: VirtualCatheter, knobs: Mapping[int, KnobModel], q: Mapping[int, np.ndarray],
                  t: np.ndarray, effects: Sequence[Effect], shape: Shape,
                  chain: Mapping[int, ChainState] | None = None,
                  current: Mapping[int, CurrentState] | None = None):
    # noise-free (tip reported by the tracker, motor current) per knob
    ys, cs = {}, {}
    for k, knob in knobs.items():
        cstate = None if current is None else current[k]
        if not effects:
            # the base model, on the very code path of KnobModel.forward
            y0 = 0.0
            if chain is not None and chain[k].y is not None:
                y0 = chain[k].y
            ys[k] = knob.forward(q[k], y0)
            if chain is not None and ys[k].size:
                chain[k].y = float(ys[k][-1])
            cs[k] = motor_current(knob, catheter.current, q[k], t, state=cstate)
            continue
        other = knobs.get(3 - k)
        tr = tip_chain(knob, k, q, t, effects, shape, 0.0, None if chain is None else chain[k],
                       other_offset=0.0 if other is None else other.offset,
                       other_knob=other if (3 - k) in q else None)
        ys[k] = tr.y
        cs[k] = motor_current(tr.knob, catheter.current, q[k], t, x=tr.x, state=cstate) \
            + contact_current(tr, effects)
    return ys, cs


def simulate(catheter: VirtualCatheter, t: np.ndarray, q: Mapping[int, np.ndarray], *,
             shape: Shape = Shape(), rotation: float = 0.0,
             effects: Sequence[Effect | EffectSpec] | None = None, seed: int = 0, noise: bool = True,
             r: Mapping[int, np.ndarray] | None = None, meta: Mapping[str, object] | None = None,
             filter_hz: float | None = 20.0) -> Run:
    """Run the virtual catheter on knob commands and record what a lab would.

    Parameters
    ----------
    catheter : VirtualCatheter
    t : numpy.ndarray
        Sample times (s), strictly increasing.
    q : mapping of int to numpy.ndarray
        Knob commands per knob (deg); 1-DoF runs give one knob.
    shape : Shape
        Shaft shape; shifts each knob by the catheter's geometry (paper eqs. 1-4) and is the
        condition of the friction and deadzone effects.
    rotation : float
        Bulk rotation of the catheter body (deg).
    effects : sequence of Effect or EffectSpec, optional
        Unmodelled effects (:mod:`hystcli.core.effects`); ``None`` means the catheter's defaults,
        ``()`` none.
    seed : int
        Seed of the sensor noise; the same arguments give the same run.
    noise : bool
        Add EM and current noise (and filter) when True; exact model output when False.
    r : mapping of int to numpy.ndarray, optional
        Reference tip angles to record beside the commands.
    meta : mapping, optional
        Extra metadata (controller, motion, trial, ...).
    filter_hz : float or None
        Cut-off of the recording filter (the paper's 20 Hz, zero-phase); None records unfiltered.

    Returns
    -------
    Run
        Columns ``t``, ``q<k>``, ``y<k>``, ``c<k>`` (and ``r<k>``) per knob; metadata with the
        catheter, shape, rotation, the true offsets ``true_offset<k>``, the effects and the seed.
        Without noise and effects, ``y<k>`` is exactly the base model's ``forward(q<k>)``.
    """
    t = np.ascontiguousarray(t, dtype=float)
    effs = as_effects(catheter.default_effects if effects is None else effects)
    rng = np.random.default_rng(seed)
    offs = catheter.true_offsets(shape, rotation)
    fs = 1.0 / float(np.median(np.diff(t))) if t.size > 1 else 1.0
    for k in q:
        if k not in catheter.knobs:
            raise ModelError(f"virtual catheter {catheter.name} has no knob {k!r}")
    knobs = {k: catheter.knobs[k].with_offset(offs[k]) for k in sorted(q)}
    qs = {k: np.ascontiguousarray(q[k], dtype=float) for k in knobs}
    for k in knobs:
        if qs[k].shape != t.shape:
            raise DataError(f"knob {k} commands have {qs[k].size} samples, t has {t.size}")
    ys, cs = _knob_signals(catheter, knobs, qs, t, effs, shape)
    cols: dict[str, np.ndarray] = {"t": t}
    for k in knobs:
        y, c = ys[k], cs[k]
        if noise:
            y = y + rng.normal(0.0, catheter.em_noise_deg, y.shape)
            c = c + rng.normal(0.0, catheter.current.noise, c.shape)
            if filter_hz is not None:
                y = lowpass(y, fs, filter_hz)
                c = lowpass(c, fs, filter_hz)
        if r is not None and k in r:
            cols[f"r{k}"] = np.asarray(r[k], dtype=float)
        cols[f"q{k}"] = qs[k]
        cols[f"y{k}"] = y
        cols[f"c{k}"] = c
    run_meta: dict[str, object] = {"catheter": catheter.name, "shape": str(shape)}
    if rotation:
        run_meta["rotation"] = f"{rotation:g}"
    for k in knobs:
        run_meta[f"true_offset{k}"] = f"{offs[k]:.6f}"
    if effs:
        run_meta["effects"] = format_effects(effs)
    run_meta["seed"] = str(seed)
    if meta:
        run_meta.update({k: v for k, v in meta.items() if v is not None})
    return Run(cols, {k: str(v) for k, v in run_meta.items()})


# --------------------------------------------------------------------------------------------
# one run of the paper's protocol (what `hyst simulate` does)
# --------------------------------------------------------------------------------------------


def run_seed(seed: int, trial: int) -> int:
    """The noise seed of trial ``trial`` of an experiment seeded ``seed`` (trials differ)."""
    return int(np.random.SeedSequence([int(seed), int(trial)]).generate_state(1)[0])


def simulate_motion(catheter: VirtualCatheter, shape: Shape = Shape(), motion: str = "periodic", *,
                    knobs: Sequence[int] | None = None, commands: Run | None = None,
                    controller: str | None = None, effects: Sequence[Effect | EffectSpec] | None = None,
                    seed: int = 0, trial: int = 1, rotation: float = 0.0, noise: bool = True) -> Run:
    """One run of the virtual catheter under a shape, a motion and a controller.

    Parameters
    ----------
    catheter : VirtualCatheter
    shape : Shape
    motion : str
        ``sweep`` (the identification sweep, +-40 deg at 40 deg/s, 2 cycles, 1 kHz),
        ``periodic`` (60 deg, 0.04 Hz, 2 cycles, 100 Hz) or ``nonperiodic`` (two sines of 30 deg,
        100 s, 100 Hz; knob 2 runs twice as fast, the paper's 2-DoF case). Ignored with
        ``commands``.
    knobs : sequence of int, optional
        Knobs to drive; default knob 1, both for ``nonperiodic``; with ``commands``, its knobs.
    commands : Run, optional
        Knob commands ``q<k>`` (and references ``r<k>``) to play instead of a generated motion,
        e.g. the output of ``hyst compensate``; its ``controller``, ``motion`` and ``offset<k>``
        metadata are kept.
    controller : str, optional
        Controller name to record; without ``commands`` only ``none`` (q = r) is possible.
    effects : sequence, optional
        Unmodelled effects; None: the catheter's defaults.
    seed, trial : int
        The noise seed is derived from both (:func:`run_seed`), so trials differ.
    rotation : float
        Bulk rotation of the body (deg).
    noise : bool
        Sensor noise and the 20 Hz filter.

    Returns
    -------
    Run
        As :func:`simulate`, with metadata catheter, controller, shape, motion, trial, seed,
        effects and true offsets.

    Raises
    ------
    DataError
        Unknown motion, a knob the commands lack, a controller other than ``none`` without
        commands.
    """
    extra: dict[str, object] = {}
    if commands is not None:
        avail = commands.knobs("q")
        if not avail:
            raise DataError(f"{commands.source or 'commands'}: no knob command column (q1 or q2)")
        use = list(avail) if knobs is None else [int(k) for k in knobs]
        for k in use:
            commands.require(f"q{k}")
        t = commands.t
        q = {k: commands[f"q{k}"] for k in use}
        r = {k: commands[f"r{k}"] for k in use if f"r{k}" in commands}
        ctrl = controller or commands.meta.get("controller") or "unknown"
        mot = commands.meta.get("motion") or "commands"
        for k in use:
            if f"offset{k}" in commands.meta:
                extra[f"offset{k}"] = commands.meta[f"offset{k}"]
    else:
        if motion not in MOTIONS:
            raise DataError(f"unknown motion {motion!r} (known: {', '.join(MOTIONS)}, or give --commands)")
        if controller not in (None, "none"):
            raise DataError(f"controller {controller!r} needs the commands it produced (--commands); "
                            "a generated motion runs with controller none")
        use = [int(k) for k in (knobs or ((1, 2) if motion == "nonperiodic" else (1,)))]
        ctrl, mot = "none", motion
        q, r = {}, {}
        for k in use:
            if motion == "sweep":
                t, q[k] = sweep()
            elif motion == "periodic":
                t, r[k] = periodic()
            else:
                t, r[k] = nonperiodic(speed=float(k) if len(use) > 1 else 1.0)
            if motion != "sweep":
                q[k] = r[k]
    for k in use:
        if k not in catheter.knobs:
            raise DataError(f"virtual catheter {catheter.name} has no knob {k}")
    meta = {"controller": ctrl, "motion": mot, "trial": str(int(trial)), **extra}
    run = simulate(catheter, t, q, shape=shape, rotation=rotation, effects=effects,
                   seed=run_seed(seed, trial), noise=noise, r=r or None, meta=meta)
    return run.with_meta(seed=str(int(seed)), effects=run.meta.get("effects", "none"))
