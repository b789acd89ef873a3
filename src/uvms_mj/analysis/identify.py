"""Identification of uncertain model parameters from recorded trials (:mod:`uvms_mj.analysis.sim2real`).

A small documented set of parameters (:data:`PARAMETERS`) is fitted by bounded nonlinear least
squares (``scipy.optimize.least_squares``, trust-region reflective) to the roll and pitch of
chosen trials: the residuals are ``sim - IMU`` roll and pitch [rad] at the IMU's time stamps of
every fit trial, simulated exactly as ``uvms-mj sim2real`` does (imposed arm motion, measured
initial state, thrusters off), all samples weighted equally.

Parameters (each: the model value it changes, its unit, default bounds):

=================  ===============================================  ======  ==================
name               model value                                      unit    bounds
=================  ===============================================  ======  ==================
cob_x, cob_y       x, y of the vehicle's centre of buoyancy          m       nominal +- 0.03
                   (``bluerov2.cob``): the rest attitude offsets
cob_z              z of ``bluerov2.cob`` (metacentric height:        m       0 .. 0.08
                   restoring stiffness in roll and pitch)
arm_volume_scale   factor on every arm link's volume (``alpha_*``)   -       0.5 .. 1.5
                   (the arm's weight in water: how far it tilts)
roll_damping,      linear rotational damping K_p, M_q of the hull    N m s   0 .. 20
pitch_damping      (``bluerov2_hull.linear_damping[3:5]``)           /rad
foam_scale         factor on both foam blocks' volume (optional)     -       0.5 .. 1.5
=================  ===============================================  ======  ==================

The optimiser works in normalised variables ``u = (x - nominal) / typical + c`` (``typical`` per
parameter: 0.01 m, 0.1, 1 N m s/rad), forward-difference Jacobian of absolute step ``diff_step``
(1e-3) in ``u``; the offset ``c = 1 / sqrt(p)`` makes the initial trust radius 1. The p + 1 simulations of every fit trial run in parallel.
Uncertainty: the covariance ``s^2 (J^T J)^-1`` at the optimum (J in physical units, ``s^2`` =
sum of squared residuals / (N - p)), inflated by ``N / N_eff`` with ``N_eff = N (1 - r1) / (1 +
r1)`` for the lag-1 autocorrelation r1 of the residuals (the 20 Hz residuals are far from
independent: without this the standard deviations would be several times too small). It still
describes only the noise-like part of the misfit, not model-form error.

Honest scores: :func:`identify` fits on ``fit`` trials and scores on disjoint ``score`` trials
(:func:`cross_validate`: K folds, each trial scored by a fit that never saw it). The fit may use a
larger step (``fit_dt``, default 0.01 s: the RMS errors change by less than 0.001 deg against the
model's 0.002 s on the Hinsdale trials, 5x faster; a check in tests/test_sim2real.py); the scores always use the sim2real settings.

The result is written as an override file (:func:`write_overrides`), the format
:func:`uvms_mj.analysis.sim2real.load_overrides` reads (``uvms-mj sim2real --overrides``).
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from uvms_mj.analysis.sim2real import (
    DEFAULT_MODEL,
    SimConfig,
    build_model,
    model_path,
    score_trial,
    simulate_trial,
)

__all__ = ["run_trials", "PARAMETERS", "DEFAULT_PARAMS", "Parameter", "IdentifyResult", "cross_validate", "identify",
           "nominal_values", "overrides_for", "write_overrides"]


@dataclass(frozen=True)
class Parameter:
    """An identifiable parameter: ``get(spec_cfg) -> nominal``, ``put(x, cfg) -> overrides``."""

    name: str
    description: str
    unit: str
    typical: float
    bounds: Callable[[float], tuple[float, float]]


ARM_BODIES = ("alpha_base", "alpha_shoulder", "alpha_upper_arm", "alpha_forearm", "alpha_wrist", "alpha_jaw")
FOAM_BODIES = ("hinsdale_foam_l", "hinsdale_foam_r")

PARAMETERS: dict[str, Parameter] = {
    p.name: p for p in (
        Parameter("cob_x", "x of the vehicle's centre of buoyancy (bluerov2.cob[0])", "m", 0.01,
                  lambda v: (v - 0.03, v + 0.03)),
        Parameter("cob_y", "y of the vehicle's centre of buoyancy (bluerov2.cob[1])", "m", 0.01,
                  lambda v: (v - 0.03, v + 0.03)),
        Parameter("cob_z", "z of the vehicle's centre of buoyancy (bluerov2.cob[2])", "m", 0.01,
                  lambda v: (0.0, 0.08)),
        Parameter("arm_volume_scale", "factor on the arm links' volumes (alpha_*.volume)", "-", 0.1,
                  lambda v: (0.5, 1.5)),
        Parameter("roll_damping", "linear roll damping K_p (bluerov2_hull.linear_damping[3])", "N m s/rad", 1.0,
                  lambda v: (0.0, 20.0)),
        Parameter("pitch_damping", "linear pitch damping M_q (bluerov2_hull.linear_damping[4])", "N m s/rad", 1.0,
                  lambda v: (0.0, 20.0)),
        Parameter("foam_scale", "factor on the foam blocks' volumes (hinsdale_foam_*.volume)", "-", 0.1,
                  lambda v: (0.5, 1.5)),
    )
}
#: The default set fitted by ``uvms-mj identify``.
#: (``arm_volume_scale`` and ``foam_scale`` are available but, on the Hinsdale trials, nearly
#: collinear with ``cob_z``: the fit then walks along a valley of almost equal cost.)
DEFAULT_PARAMS = ("cob_x", "cob_y", "cob_z", "roll_damping", "pitch_damping")
#: Default relative tolerance of the cost (and of the step) ending the fit.
DEFAULT_TOL = 1e-4
#: Default physics step of the fit [s] (scores use the sim2real step).
DEFAULT_FIT_DT = 0.01


def _spec_values(model, base: Mapping[str, Any]) -> dict:
    """The model values the parameters act on (after the base overrides)."""
    from uvms_mj.physics.model import body_config, load_spec
    from uvms_mj.analysis.sim2real import apply_trial_overrides

    spec = load_spec(model_path(model))
    apply_trial_overrides(spec, base)
    nums = lambda s: [float(x) for x in str(s).split()]  # noqa: E731
    vals = {"cob": nums(body_config(spec, "bluerov2").get("cob", "0 0 0")),
            "lin": nums(body_config(spec, "bluerov2_hull").get("linear_damping", "0 0 0 0 0 0")),
            "arm": {b: nums(body_config(spec, b).get("volume", "0"))[0] for b in ARM_BODIES},
            "foam": {b: nums(body_config(spec, b).get("volume", "0"))[0] for b in FOAM_BODIES}}
    return vals


def nominal_values(model=DEFAULT_MODEL, names: Sequence[str] = DEFAULT_PARAMS,
                   base: Mapping[str, Any] | None = None) -> np.ndarray:
    """Nominal values of the named parameters in the model (after ``base`` overrides)."""
    v = _spec_values(model, base or {})
    table = {"cob_x": v["cob"][0], "cob_y": v["cob"][1], "cob_z": v["cob"][2], "arm_volume_scale": 1.0,
             "roll_damping": v["lin"][3], "pitch_damping": v["lin"][4], "foam_scale": 1.0}
    return np.array([table[n] for n in names])


def overrides_for(model, names: Sequence[str], x: Sequence[float], base: Mapping[str, Any] | None = None) -> dict:
    """The override entries (``"BODY.ATTRIBUTE": value``) that set the parameters to ``x``."""
    base = dict(base or {})
    v = _spec_values(model, base)
    out = dict(base)
    val = dict(zip(names, map(float, x)))
    if {"cob_x", "cob_y", "cob_z"} & set(val):
        c = list(v["cob"])
        for i, n in enumerate(("cob_x", "cob_y", "cob_z")):
            c[i] = val.get(n, c[i])
        out["bluerov2.cob"] = c
    if {"roll_damping", "pitch_damping"} & set(val):
        lin = list(v["lin"])
        lin[3] = val.get("roll_damping", lin[3])
        lin[4] = val.get("pitch_damping", lin[4])
        out["bluerov2_hull.linear_damping"] = lin
    if "arm_volume_scale" in val:
        for b, vol in v["arm"].items():
            out[f"{b}.volume"] = vol * val["arm_volume_scale"]
    if "foam_scale" in val:
        for b, vol in v["foam"].items():
            out[f"{b}.volume"] = vol * val["foam_scale"]
    return out


# ------------------------------------------------------------------------------ evaluation

_WORKER: dict = {}


def _init_worker(trials, model, cfg, keep_sim=False):
    _WORKER.update(trials={t.name: t for t in trials}, model=model, cfg=cfg, keep_sim=keep_sim)
    from uvms_mj.physics import build

    build.register_plugins()  # once per worker process (build_model's loader would do it on first use)


def _sim_job(args):
    name, overrides, cfg = args
    cfg = cfg or _WORKER["cfg"]
    tr = _WORKER["trials"][name]
    m = build_model(_WORKER["model"], overrides, neutral=cfg.neutral)
    sim = simulate_trial(m, tr, cfg)
    imu = tr.imu
    sel = (imu.t >= sim.t[0]) & (imu.t <= sim.t[-1])
    res = np.concatenate([np.interp(imu.t[sel], sim.t, sim.roll) - imu.roll[sel],
                          np.interp(imu.t[sel], sim.t, sim.pitch) - imu.pitch[sel]])
    return name, res, score_trial(tr, sim, cfg), (sim if _WORKER.get("keep_sim") else None)


class _Evaluator:
    """Simulates trials for parameter vectors (in parallel over trials)."""

    def __init__(self, trials, model, cfg: SimConfig, jobs: int, keep_sim: bool = False):
        self.trials, self.model, self.cfg = list(trials), model, cfg
        self.jobs = max(1, int(jobs))
        self.pool = None
        if self.jobs > 1 and len(self.trials) > 1:
            import multiprocessing as mp
            from concurrent.futures import ProcessPoolExecutor

            ctx = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else mp.get_context("spawn")
            self.pool = ProcessPoolExecutor(self.jobs, mp_context=ctx, initializer=_init_worker,
                                            initargs=(self.trials, model, cfg, keep_sim))
        else:
            _init_worker(self.trials, model, cfg, keep_sim)

    def run(self, overrides, names: Sequence[str], cfg: SimConfig | None = None):
        return self.run_many([overrides], names, cfg)[0]

    def run_many(self, overrides_list, names: Sequence[str], cfg: SimConfig | None = None):
        """One result dict per overrides (all simulations spread over the workers)."""
        jobs = [(n, o, cfg) for o in overrides_list for n in names]
        if self.pool is not None:
            out = list(self.pool.map(_sim_job, jobs))
        else:
            out = [_sim_job(j) for j in jobs]
        k = len(names)
        return [{n: (r, s, sim) for n, r, s, sim in out[i * k:(i + 1) * k]} for i in range(len(overrides_list))]

    def close(self):
        if self.pool is not None:
            self.pool.shutdown()


@dataclass
class IdentifyResult:
    """Result of :func:`identify` (angles of the scores in degrees).

    Attributes:
        names, units: the fitted parameters; nominal, value, std: their values [SI];
        bounds: (p, 2); fit, score: trial names; before, after: trial -> TrialScore (nominal and
        identified model, scored with the sim2real settings) for the fit and score trials;
        overrides: the override entries of the identified values; corr: (p, p) correlation of
        the estimates; nfev: simulations of the fit set; cost0, cost: RMS of the fit residuals
        [deg] before and after; n_eff_factor: N / N_eff of the uncertainty; message.
    """

    names: list
    units: list
    nominal: list
    value: list
    std: list
    bounds: list
    fit: list
    score: list
    before: dict
    after: dict
    overrides: dict
    corr: list
    nfev: int
    cost0: float
    cost: float
    n_eff_factor: float
    message: str = ""
    fit_dt: float | None = None

    def to_json(self) -> dict:
        d = {k: v for k, v in asdict(self).items() if k not in ("before", "after")}
        d["before"] = {k: v.to_json() for k, v in self.before.items()}
        d["after"] = {k: v.to_json() for k, v in self.after.items()}
        d["summary"] = self.summary()
        return d

    def summary(self) -> dict:
        """Mean RMS roll / pitch [deg] of the fit and score trials, before and after."""
        out = {}
        for group, names in (("fit", self.fit), ("score", self.score)):
            for when, sc in (("before", self.before), ("after", self.after)):
                rows = [sc[n] for n in names if n in sc]
                out[f"{group}_{when}"] = {
                    "rms_roll": float(np.mean([r.rms_roll for r in rows])) if rows else math.nan,
                    "rms_pitch": float(np.mean([r.rms_pitch for r in rows])) if rows else math.nan,
                    "max_rms": float(max([max(r.rms_roll, r.rms_pitch) for r in rows])) if rows else math.nan}
        return out


def _residual_factor(r: np.ndarray) -> float:
    """N / N_eff from the lag-1 autocorrelation of the residuals (>= 1)."""
    r = r - r.mean()
    den = float(r @ r)
    if den == 0 or len(r) < 3:
        return 1.0
    r1 = float(np.clip((r[1:] @ r[:-1]) / den, 0.0, 0.999))
    return (1 + r1) / (1 - r1)


def identify(trials: Mapping[str, Any] | Iterable, fit: Sequence[str], score: Sequence[str] = (),
             names: Sequence[str] = DEFAULT_PARAMS, model=DEFAULT_MODEL, base: Mapping[str, Any] | None = None,
             cfg: SimConfig = SimConfig(), fit_dt: float | None = DEFAULT_FIT_DT, max_nfev: int = 40,
             diff_step: float = 1e-3, tol: float = DEFAULT_TOL, jobs: int | None = None, x0: Sequence[float] | None = None,
             bounds: Mapping[str, tuple[float, float]] | None = None,
             progress: Callable[[str], None] | None = None) -> IdentifyResult:
    """Fit the parameters ``names`` on the ``fit`` trials and score the ``score`` trials.

    Args:
        trials: name -> :class:`uvms_mj.analysis.trials.Trial` (or an iterable of trials).
        fit, score: trial names (must be disjoint for an honest score).
        names: parameters of :data:`PARAMETERS`.
        model: model name or path; base: overrides applied first (their values are the nominal).
        cfg: the sim2real settings (used for the scores); fit_dt: the physics step of the fit
            (None: ``cfg.dt``).
        max_nfev: most residual evaluations of the optimiser (each Jacobian adds p more);
            diff_step: finite-difference step in the normalised variables (absolute);
            tol: relative tolerance of the cost and of the step (scipy's ftol, xtol); jobs: worker processes (default: min(2, CPUs)).
        x0: start values (default: the nominal); bounds: name -> (lo, hi) replacing defaults.

    Raises:
        ValueError: unknown parameter or trial, overlapping fit and score, no fit trial.
    """
    from scipy.optimize import least_squares

    tmap = dict(trials) if isinstance(trials, Mapping) else {t.name: t for t in trials}
    unknown = [n for n in names if n not in PARAMETERS]
    if unknown:
        raise ValueError(f"unknown parameter(s) {', '.join(unknown)} (known: {', '.join(PARAMETERS)})")
    for n in list(fit) + list(score):
        if n not in tmap:
            raise ValueError(f"trial {n!r} is not among the loaded trials ({', '.join(sorted(tmap))})")
    if not fit:
        raise ValueError("no fit trials")
    both = sorted(set(fit) & set(score))
    if both:
        raise ValueError(f"trial(s) {', '.join(both)} both fitted and scored: the score would not be a prediction")
    base = dict(base or {})
    nominal = nominal_values(model, names, base)
    typical = np.array([PARAMETERS[n].typical for n in names])
    bl = np.array([(bounds or {}).get(n, PARAMETERS[n].bounds(v)) for n, v in zip(names, nominal)], float)
    start = nominal if x0 is None else np.asarray(x0, float)
    start = np.clip(start, bl[:, 0], bl[:, 1])
    jobs = jobs or min(2, os.cpu_count() or 1)
    fcfg = cfg if fit_dt is None else replace(cfg, dt=fit_dt)
    ev = _Evaluator(tmap.values(), model, cfg, jobs)
    say = progress or (lambda s: None)
    try:
        count = [0]
        cache: dict = {}
        # u = (x - nominal) / typical + c: the offset c keeps |u0| = 1, the optimiser's initial
        # trust radius (scipy takes |u0|, which would be ~0 at the nominal)
        c = 1.0 / math.sqrt(len(names))

        def phys(u):
            return nominal + typical * (np.asarray(u, float) - c)

        def sims(us):
            """Residual vectors of several normalised parameter vectors (one parallel batch)."""
            todo = [u for u in us if tuple(u) not in cache]
            if todo:
                outs = ev.run_many([overrides_for(model, names, phys(u), base) for u in todo], fit, fcfg)
                for u, out in zip(todo, outs):
                    r = np.concatenate([out[n][0] for n in fit])
                    if not np.all(np.isfinite(r)):
                        raise RuntimeError("a fit simulation returned non-finite attitudes")
                    cache[tuple(u)] = r
                count[0] += len(todo)
            return [cache[tuple(u)] for u in us]

        def resid(u):
            r = sims([np.asarray(u, float)])[0]
            say(f"  eval {count[0]:3d}: RMS {math.degrees(float(np.sqrt(np.mean(r ** 2)))):.4f} deg  "
                + " ".join(f"{n}={v:.5g}" for n, v in zip(names, phys(u))))
            return r

        lo, hi = (bl[:, 0] - nominal) / typical + c, (bl[:, 1] - nominal) / typical + c

        def jac(u):
            # forward differences of absolute step diff_step in u (backward at an upper bound),
            # all columns simulated in one parallel batch
            u = np.asarray(u, float)
            steps = np.where(u + diff_step <= hi, diff_step, -diff_step)
            pts = [u] + [u + steps[i] * np.eye(len(u))[i] for i in range(len(u))]
            rs = sims(pts)
            return np.column_stack([(rs[i + 1] - rs[0]) / steps[i] for i in range(len(u))])

        u0 = (start - nominal) / typical + c
        r0 = resid(u0)
        sol = least_squares(resid, u0, jac=jac, bounds=(lo, hi), method="trf", x_scale=1.0, max_nfev=max_nfev,
                            ftol=tol, xtol=tol)
        x = phys(sol.x)
        r = sol.fun
        J = sol.jac / typical[None, :]
        N, p = len(r), len(names)
        s2 = float(r @ r) / max(1, N - p)
        fac = _residual_factor(r)
        try:
            cov = np.linalg.inv(J.T @ J) * s2 * fac
            std = np.sqrt(np.clip(np.diag(cov), 0, None))
            corr = cov / np.outer(std, std)
        except np.linalg.LinAlgError:
            std = np.full(p, math.nan)
            corr = np.full((p, p), math.nan)
        over = overrides_for(model, names, x, base)
        allnames = list(fit) + list(score)
        before = {n: v[1] for n, v in ev.run(base, allnames, cfg).items()}
        after = {n: v[1] for n, v in ev.run(over, allnames, cfg).items()}
    finally:
        ev.close()
    return IdentifyResult(
        names=list(names), units=[PARAMETERS[n].unit for n in names], nominal=nominal.tolist(), value=x.tolist(),
        std=std.tolist(), bounds=bl.tolist(), fit=list(fit), score=list(score), before=before, after=after,
        overrides=over, corr=np.asarray(corr).tolist(), nfev=int(count[0]),
        cost0=math.degrees(float(np.sqrt(np.mean(r0 ** 2)))), cost=math.degrees(float(np.sqrt(np.mean(r ** 2)))),
        n_eff_factor=float(fac), message=str(sol.message), fit_dt=fcfg.dt)


def folds(names: Sequence[str], k: int) -> list[list[str]]:
    """Split sorted trial names round-robin into ``k`` folds (deterministic)."""
    if k < 2:
        raise ValueError(f"cross-validation needs at least 2 folds, got {k}")
    names = sorted(names)
    if len(names) < k:
        raise ValueError(f"{k} folds need at least {k} trials, got {len(names)}")
    return [names[i::k] for i in range(k)]


def cross_validate(trials: Mapping[str, Any], k: int = 2, **kw) -> list[IdentifyResult]:
    """K-fold cross-validation: fold i is scored with parameters fitted on the other folds."""
    out = []
    parts = folds(list(trials), k)
    for i, part in enumerate(parts):
        fit = [n for j, p in enumerate(parts) if j != i for n in p]
        out.append(identify(trials, fit=fit, score=part, **kw))
    return out


def write_overrides(path: str | Path, overrides: Mapping[str, Any], header: str = "") -> Path:
    """Write an override file (YAML ``"BODY.ATTRIBUTE": value``), with ``header`` as comments."""
    import yaml

    p = Path(path)
    clean = {k: (float(v[0]) if isinstance(v, (list, tuple)) and len(v) == 1 else
                 [float(x) for x in v] if isinstance(v, (list, tuple)) else float(v)) for k, v in overrides.items()}
    text = "".join(f"# {line}\n" for line in header.splitlines()) + yaml.safe_dump(clean, sort_keys=True,
                                                                                     default_flow_style=None)
    from uvms_mj.io.atomic import atomic_open

    with atomic_open(p, "w", mkdir=False, encoding="utf-8") as f:
        f.write(text)
    return p


def run_trials(trials: Iterable, model=DEFAULT_MODEL, overrides: Mapping[str, Any] | None = None,
               cfg: SimConfig = SimConfig(), jobs: int | None = None) -> dict:
    """Simulate and score trials (in parallel): name -> (SimResult, TrialScore)."""
    trials = list(trials)
    ev = _Evaluator(trials, model, cfg, jobs or min(2, os.cpu_count() or 1), keep_sim=True)
    try:
        out = ev.run(dict(overrides or {}), [t.name for t in trials], cfg)
    finally:
        ev.close()
    return {n: (v[2], v[1]) for n, v in out.items()}
