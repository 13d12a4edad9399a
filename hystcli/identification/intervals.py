"""What a record fixes of each tip parameter: profile-likelihood intervals.

For a parameter ``p`` of the loop (``d_pos`` ... ``h_neg``, each a function of the fit's unknowns)
the profile deviance at a value ``v`` is the best fit's deviance with ``p`` held at ``v`` and every
other unknown refitted (the loop's, and any wall's level). The interval at the settings' level is
the set of values whose profile stays within the chi-square(1) quantile of the best, the deviance
rise divided by the residuals' autocorrelation time (a filtered tracker's neighbouring samples
share one noise draw). Walking out from the fit in doubling steps, each crossing is bisected; a
side that never crosses before the parameter leaves the range the record could say anything about
is open: the record does not fix the parameter there, and says so (``b_pos >= 5.4``).

A profile that finds a better fit than the fit itself restarts from it: the profile is a search
too.
"""
from __future__ import annotations

import math

import numpy as np

from ..estimate import Estimate
from ..settings import DEFAULT, Settings
from ..signal.pwl import autocorrelation_time
from ..signal.stretches import decimation_index
from .tip import (PARAMS, LoopFit, TipFit, _clip_residuals, _params, _params_jacobian, model_of, predict,
                  refine_clipped)

__all__ = ["tip_intervals"]

PROFILE_SAMPLES = 1000
"""Most samples a profile refit evaluates (a computation budget; reversals kept)."""

BISECTIONS = 4
"""Halvings of a crossing the quadratic guess missed (a computation budget)."""

HINTS = {
    "d_pos": "the tip never leaves the dead zone far enough on the positive side: sweep further that way",
    "d_neg": "the tip never leaves the dead zone far enough on the negative side: sweep further that way",
    "b_pos": "after the top reversal the tip never comes down off its backlash plateau: reverse from further up",
    "b_neg": "after the bottom reversal the tip never rises off its backlash plateau: reverse from further down",
    "omega": "the loaded slopes are too short to fix the slope",
    "h_pos": "the rising dead zone's height is not seen apart from its edge",
    "h_neg": "the falling dead zone's height is not seen apart from its edge",
}
"""Why the record may leave a parameter open, in the user's terms."""


def _limits(name: str, v: float, q: np.ndarray, y: np.ndarray, omega: float) -> tuple[float, float, bool, bool]:
    """(low, high, low is the domain's bound, high is the domain's bound) of the walk for ``name``:
    past a range limit the record can say nothing, a domain bound closes the interval there."""
    span = float(np.ptp(q)) or 1.0
    if name in ("d_pos", "d_neg"):
        return float(np.min(q)) - span, float(np.max(q)) + span, False, False
    if name in ("b_pos", "b_neg"):
        return 0.0, 2.0 * span, True, False
    if name == "omega":
        return 1e-3, max(20.0 * omega, 10.0), True, False
    ys = float(np.ptp(y)) or 1.0
    return float(np.min(y)) - 2.0 * ys, float(np.max(y)) + 2.0 * ys, False, False


def _wald_se(loop: LoopFit, q: np.ndarray, y: np.ndarray, noise: float, tau: float) -> np.ndarray:
    """Gauss-Newton standard errors of the seven parameters (a first step for the walk)."""
    from .tip import _clip_jacobian

    jac = _clip_jacobian(loop.p, q, y, loop.sides)
    norms = np.sqrt(np.sum(jac * jac, axis=0))
    norms = np.where(norms > 0, norms, 1.0)
    js = jac / norms
    try:
        inv = np.linalg.pinv(js.T @ js, rcond=1e-10)
    except np.linalg.LinAlgError:
        return np.full(len(PARAMS), math.inf)
    cov = inv / np.outer(norms, norms) * noise ** 2 * max(tau, 1.0)
    g = np.zeros((len(PARAMS), loop.p.size))
    g[:, :8] = _params_jacobian(loop.theta)
    return np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", g, cov, g), 0.0))


def tip_intervals(fit: TipFit, settings: Settings = DEFAULT) -> tuple[dict[str, Estimate], TipFit]:
    """Each of :data:`PARAMS` as an :class:`~hystcli.estimate.Estimate` with its profile interval.

    Returns
    -------
    (dict of str to Estimate, TipFit)
        The estimates, and the fit (a better one when a profile found it).
    """
    idx = decimation_index(fit.q, PROFILE_SAMPLES)
    q = np.ascontiguousarray(fit.q[idx])
    y = np.ascontiguousarray(fit.y[idx])
    f_scale, noise = fit.f_scale, max(fit.noise, 1e-9)
    best = refine_clipped(fit.loop.p, q, y, fit.loop.sides, f_scale, noise)
    tau = autocorrelation_time(_clip_residuals(best.p, q, y, best.sides))
    chi2 = settings.chi2
    improved = False
    for attempt in range(4):
        # the last attempt takes the intervals as they come, better optima or not
        out, better = _walk_all(best, q, y, f_scale, noise, tau, chi2, settings.level, restart=attempt < 3)
        if better is None:
            break
        best = refine_clipped(better.p, q, y, better.sides, f_scale, noise)
        improved = True
    if improved:
        # a better optimum the profile found replaces the fit only where it is better on all the
        # fit's samples too
        full = refine_clipped(best.p, fit.q, fit.y, best.sides, f_scale, noise)
        if full.deviance < fit.loop.deviance - 1e-9:
            from dataclasses import replace

            fit = replace(fit, loop=full, model=model_of(full.theta))
    if best.sides == (False, False) and fit.grid:
        out = _with_distant_optima(out, best, fit, noise, chi2, settings.chi2_ambiguity)
    span = float(np.ptp(fit.q)) or 1.0
    return {n: _judged(n, e, settings.max_fixed_halfwidth, span) for n, e in out.items()}, fit


def _with_distant_optima(out: dict[str, Estimate], best: LoopFit, fit: TipFit, noise: float, chi2: float,
                         chi2_ambiguity: float) -> dict[str, Estimate]:
    """Each interval widened to the distant loops that fit the record about as well.

    A profile walked from the best fit sees its own valley only, and a record may hold distant
    loops that fit it as well. Two sources, both on the global search's samples: every grid
    geometry within the level's bound (a grid point's sum of squares, before any refinement, can
    only overstate its valley's deviance), and every local optimum the fit's starts reached within
    the ambiguity level's bound (a parameter must not be reported fixed when it hangs on which of
    two near-equal optima the search ended in).
    """
    from dataclasses import replace

    cands, sse, qs, ys = fit.grid
    r = predict(best.theta, qs) - ys
    tau = max(autocorrelation_time(r), 1.0)
    var = max(noise, 1e-12) ** 2 * tau
    inside = (sse - float(r @ r)) / var <= chi2
    values = [_params_of_geometry(g) for g in cands[inside]]
    for th in fit.alternatives:
        ra = predict(th, qs) - ys
        if (float(ra @ ra) - float(r @ r)) / var <= chi2_ambiguity:
            values.append(dict(zip(PARAMS, map(float, _params(th)))))
    new = dict(out)
    for name in ("d_pos", "d_neg", "b_pos", "b_neg", "omega", "h_pos", "h_neg"):
        v = [p[name] for p in values if name in p]
        if v:
            e = out[name]
            new[name] = replace(e, lo=min(e.lo, min(v)), hi=max(e.hi, max(v)))
    return new


def _params_of_geometry(g: np.ndarray) -> dict[str, float]:
    dn, dp, bp, bn, _ = map(float, g)
    return {"d_neg": dn, "d_pos": dp, "b_pos": bp, "b_neg": bn}


def _judged(name: str, e: Estimate, max_halfwidth: float, span: float) -> Estimate:
    """The estimate marked fixed only when its interval is closed and the tip it predicts moves by
    less than ``max_halfwidth`` deg across it (omega over half the swept range)."""
    from dataclasses import replace

    if not e.fixed:
        return e
    scale = 0.5 * span if name == "omega" else 1.0
    if e.halfwidth * scale <= max_halfwidth:
        return e
    unit = "" if name == "omega" else " deg"
    return replace(e, fixed=False, reason=(f"the record bounds it only to [{e.lo:.2f}, {e.hi:.2f}]{unit}, across "
                                           f"which the predicted tip moves by more than {max_halfwidth:g} deg"))


class _Better(Exception):
    """A profile refit found a better optimum than the fit it walks from."""

    def __init__(self, fit: LoopFit) -> None:
        super().__init__("a better optimum")
        self.fit = fit


def _walk_all(best: LoopFit, q, y, f_scale, noise, tau, chi2, level, restart=True):  # noqa: ANN001, ANN202
    """Every parameter's interval: (estimates, None), or (partial, a better fit) to restart from."""
    values = _params(best.theta)
    se = _wald_se(best, q, y, noise, tau)
    span = float(np.ptp(q)) or 1.0
    out: dict[str, Estimate] = {}
    for j, name in enumerate(PARAMS):
        v0 = float(values[j])
        lo_lim, hi_lim, lo_dom, hi_dom = _limits(name, v0, q, y, float(values[4]))
        step0 = float(se[j]) * math.sqrt(chi2) if math.isfinite(se[j]) and se[j] > 0 else 0.05 * span
        step0 = min(max(step0, 1e-3 * (span if name != "omega" else 1.0)), 0.25 * span)
        walk = _Profile(best, q, y, f_scale, noise, tau, chi2, j, v0, restart)
        try:
            lo = walk.end(-1.0, step0, lo_lim, lo_dom)
            hi = walk.end(1.0, step0, hi_lim, hi_dom)
        except _Better as better:
            return out, better.fit
        lo, hi = min(lo, v0), max(hi, v0)
        closed = math.isfinite(lo) and math.isfinite(hi)
        out[name] = Estimate(v0, lo, hi, level, closed, None if closed else HINTS[name])
    return out, None


def _penalty(j: int, v: float, weight: float):  # noqa: ANN202
    def extra(p: np.ndarray) -> np.ndarray:
        return np.array([weight * (_params(p[:8])[j] - v)])

    def extra_jac(p: np.ndarray) -> np.ndarray:
        row = np.zeros((1, p.size))
        row[0, :8] = weight * _params_jacobian(p[:8])[j]
        return row

    return extra, extra_jac


class _Profile:
    """One parameter's profile deviance, walked out from the fit on either side."""

    def __init__(self, best: LoopFit, q, y, f_scale, noise, tau, chi2, j, v0, restart) -> None:  # noqa: ANN001
        self.best, self.q, self.y = best, q, y
        self.f_scale, self.noise, self.tau, self.chi2 = f_scale, noise, max(tau, 1.0), chi2
        self.j, self.v0, self.restart = j, v0, restart
        self.weight = 1e3 * math.sqrt(q.size) * f_scale

    def rise(self, v: float, start: np.ndarray) -> tuple[float, np.ndarray]:
        """The deviance rise (over tau) with the parameter held at ``v``, and the refit's unknowns."""
        got = refine_clipped(start, self.q, self.y, self.best.sides, self.f_scale, self.noise,
                             penalty=_penalty(self.j, v, self.weight), max_nfev=40)
        r = _clip_residuals(got.p, self.q, self.y, got.sides)
        dev = float(np.sum(2.0 * (np.sqrt(1.0 + (r / self.f_scale) ** 2) - 1.0))) * self.f_scale ** 2 / self.noise ** 2
        d = (dev - self.best.deviance) / self.tau
        if d < -0.5 and self.restart:
            raise _Better(LoopFit(got.p, got.sides, dev))
        return d, got.p

    def end(self, sign: float, step: float, limit: float, at_domain: bool) -> float:
        """Where the rise crosses chi2 on side ``sign`` (the domain's bound, or +-inf, where it never
        does before ``limit``): a first probe, the quadratic guess it suggests, then doubling
        steps, then bisection of the crossing."""
        v0, chi2 = self.v0, self.chi2
        start = self.best.p
        hit = sign * (v0 + sign * step - limit) >= 0
        v = limit if hit else v0 + sign * step
        d, start = self.rise(v, start)
        if not hit and abs(d - chi2) < 0.2 * chi2:
            return v
        inside, outside = v0, None
        if not hit and 0.25 * chi2 < d < 4.0 * chi2:
            guess = v0 + sign * step * math.sqrt(chi2 / d)
            dg, start = self.rise(guess, start)
            if abs(dg - chi2) < 0.2 * chi2:
                return guess
            pts = sorted([(v, d), (guess, dg)], key=lambda p: abs(p[0] - v0))
            inside = max([p[0] for p in pts if p[1] <= chi2] or [v0], key=lambda u: abs(u - v0))
            outside = next((p[0] for p in pts if p[1] > chi2), None)
        elif d > chi2:
            outside = v
        else:
            inside = v
        while outside is None:
            if sign * (inside - limit) >= 0:
                return limit if at_domain else sign * math.inf
            v = v0 + sign * max(2.0 * abs(inside - v0), step)
            v = limit if sign * (v - limit) >= 0 else v
            d, start = self.rise(v, start)
            if d > chi2:
                outside = v
            else:
                inside = v
        return self._bisect(inside, outside, start)

    def _bisect(self, a: float, b: float, start: np.ndarray) -> float:
        for _ in range(BISECTIONS):
            m = 0.5 * (a + b)
            d, start = self.rise(m, start)
            if d > self.chi2:
                b = m
            else:
                a = m
        return 0.5 * (a + b)
