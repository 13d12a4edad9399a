"""The virtual catheter: a seeded simulator of the physical system the paper measured.

It owns the true parameters of named virtual catheters, the motions of the paper's protocol
(sweep, periodic, non-periodic), the motor-current model of DESIGN.md section 4 and the sensor
chain (EM-tracker noise, 20 Hz Butterworth). The demo, the tests, the sample data and the serial
emulator all draw their data from :func:`simulate`.

Motor current (signed, mA), for knob angle ``u`` relative to the shifted edges::

    T      = k_load * ((u - d~_pos)+ - (d~_neg - u)+)      tendon tension: 0 while both are slack
    phi    = play operator on u of width b (in [-1, 1])     +1 while pulling the anterior tendon
    c      = c_no_load + c_coulomb * tanh(dq/dt / v_s) + T + mu * |T| * phi + noise

So the current is flat in the dead zone (no tendon taut), rises with slope ``k_load (1 +- mu)``
once a tendon is taut, and after a reversal falls steeply by ``2 mu |T|`` over the backlash width
``b`` while the sheath friction changes sign (the current's signature of backlash). Contact with
a wall adds a far steeper term (the ``contact`` effect).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Mapping, Sequence

import numpy as np
from numba import njit

from .errors import DataError, ModelError
from .filters import lowpass
from .io import Run
from .model import EffectSpec, Geometry, KnobModel, Model, Shape


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
        Sheath friction ratio: the loading slope is ``k_load (1 + mu)``, unloading ``k_load (1 - mu)``.
    noise : float
        White current noise before the 20 Hz filter (mA rms).
    """

    no_load: float = 120.0
    coulomb: float = 6.0
    v_smooth: float = 0.5
    k_load: float = 4.0
    mu: float = 0.25
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


# The two virtual ICE catheters, like the paper's two. Edges and backlash of the order of the
# DESIGN.md example; beta_catheter / beta_knob from a 10 Fr shaft (tendons ~1.2 mm off axis) and
# an 8 mm knob pulley.
CATHETERS: Mapping[str, VirtualCatheter] = MappingProxyType({
    "ice-a": VirtualCatheter(
        "ice-a",
        {1: KnobModel(d_pos=9.1, d_neg=-8.7, b_pos=6.2, b_neg=5.9, omega=1.45, h_pos=-4.0, h_neg=4.2),
         2: KnobModel(d_pos=8.4, d_neg=-9.3, b_pos=5.6, b_neg=6.4, omega=1.40, h_pos=-3.6, h_neg=3.9)},
        Geometry(beta_catheter_mm=1.2, beta_knob_mm=8.0),
    ),
    "ice-b": VirtualCatheter(
        "ice-b",
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
# motions of the paper's protocol (DESIGN.md section 7)
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
def _play(u, width, phi0, out):
    # play (backlash) operator normalised to [-1, 1]: moves 2/width per degree of knob travel
    phi = phi0
    prev = u[0]
    for i in range(u.shape[0]):
        if width[i] > 0:
            phi += 2.0 * (u[i] - prev) / width[i]
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


def motor_current(knob: KnobModel, cur: CurrentParams, q: np.ndarray, t: np.ndarray,
                  phi0: float = 0.0) -> np.ndarray:
    """Noise-free motor current (mA) of one knob for commands ``q`` at times ``t``.

    ``knob`` carries the shift in its ``offset``; see the module docstring for the model.
    """
    u = np.asarray(q, float) - knob.offset
    tension = cur.k_load * (np.maximum(u - knob.d_pos, 0.0) - np.maximum(knob.d_neg - u, 0.0))
    # the friction play uses the backlash width of the side whose tendon is taut
    width = np.where(u >= 0.5 * (knob.d_pos + knob.d_neg), knob.b_pos, knob.b_neg)
    phi = np.empty_like(u)
    if u.size:
        _play(u, width, phi0, phi)
    v = np.gradient(np.asarray(q, float), t) if len(t) > 1 else np.zeros_like(u)
    return cur.no_load + cur.coulomb * np.tanh(v / cur.v_smooth) + tension + cur.mu * np.abs(tension) * phi


def simulate(catheter: VirtualCatheter, t: np.ndarray, q: Mapping[int, np.ndarray], *,
             shape: Shape = Shape(), rotation: float = 0.0,
             effects: Sequence[EffectSpec] | None = None, seed: int = 0, noise: bool = True,
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
        Shaft shape; shifts each knob by the catheter's geometry (paper eqs. 1-4).
    rotation : float
        Bulk rotation of the catheter body (deg).
    effects : sequence of EffectSpec, optional
        Unmodelled effects; ``None`` means the catheter's defaults, ``()`` none.
    seed : int
        Seed of the sensor noise; the same arguments give the same run.
    noise : bool
        Add EM and current noise (and filter) when True; exact model output when False.
    r : mapping of int to numpy.ndarray, optional
        Reference tip angles to record beside the commands.
    meta : mapping, optional
        Extra metadata (controller, motion, trial, ...).
    filter_hz : float or None
        Cut-off of the recording filter (the paper's 20 Hz); None records unfiltered.

    Returns
    -------
    Run
        Columns ``t``, ``q<k>``, ``y<k>``, ``c<k>`` (and ``r<k>``) per knob, metadata with the
        catheter, shape, rotation and the true offsets.
    """
    from . import effects as effects_mod  # effects build on the twin's signals

    t = np.asarray(t, dtype=float)
    if effects is None:
        effects = catheter.default_effects
    rng = np.random.default_rng(seed)
    offs = catheter.true_offsets(shape, rotation)
    fs = 1.0 / float(np.median(np.diff(t))) if t.size > 1 else 1.0
    knobs = {k: catheter.knobs[k].with_offset(offs[k]) for k in sorted(q)}
    qs = {k: np.asarray(q[k], dtype=float) for k in knobs}
    ys, cs = effects_mod.apply(list(effects), catheter, knobs, qs, t, shape)
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
    if effects:
        run_meta["effects"] = ";".join(
            e.name + ("(" + ",".join(f"{p}={v:g}" for p, v in e.params.items()) + ")" if e.params else "")
            for e in effects)
    run_meta["seed"] = str(seed)
    if meta:
        run_meta.update({k: v for k, v in meta.items() if v is not None})
    return Run(cols, {k: str(v) for k, v in run_meta.items()})
