"""A run's metrics (:data:`METRIC_KEYS`), accumulated block by block so that memory never grows.

:class:`RunMetrics` takes the run's samples in blocks of consecutive samples (any size: the
sampled loop gives them as it records, a log reader as it reads, a finished run all at once) and
re-cuts them into blocks of :data:`BLOCK` samples aligned on the run's sample index, on which
every partial sum, maximum and count is taken. The numbers therefore do not depend on how the
samples were handed in: a run streamed through the loop without keeping its signals
(``run_closed_loop(keep=False)``, what the CLI does) gives the same metrics as :func:`metrics` of
the same run kept whole or read back from its log. Memory: at most two blocks of the few signals
the metrics read.

The metrics (true state against the desired one; every error is the true signal, not the
measurement):

* planar robot (the paper's): base position error |p_d - p| (x, y) [mm], attitude |phi_d - phi|
  [mrad], tip |tip_d - tip| [mm] (``p_desired`` = (x, y, phi, tip x, tip y));
* floating robot (any MJCF robot): base position |p_d - p| [mm] (world), attitude: the angle of
  the rotation between desired and true orientation, 2 acos |<q_d, q>| [mrad]; tip against
  ``tip_desired`` (world); ``joint_rms_mrad``: RMS over samples and joints of q_d - q;
* RMS thrust [N] and joint torque [N m] (what the thrusters and motors applied), ``saturated_s``
  (time with a thruster at its force limit), ``joint_limit_excursion_deg``
  (:func:`uvms_mj.sim.limits.joint_limit_excursion`), ``singular_s`` (time in Eq. 12's singular
  phase), ``nav_pos_rms_mm`` / ``nav_att_rms_mrad`` (the online estimate's own error).

A metric whose signals are missing is NaN; nothing here raises for a short or broken run.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from uvms_mj.sim.limits import joint_limit_excursion

__all__ = ["BLOCK", "METRIC_KEYS", "RunMetrics", "metrics"]

#: Samples per block of the partial sums (ours: 1024 keeps the pending signals near 0.5 MB on a
#: floating robot and the per-block numpy overhead below 0.1 µs per sample).
BLOCK = 1024

METRIC_KEYS = ("base_pos_rms_mm", "base_pos_max_mm", "base_att_rms_mrad", "base_att_max_mrad", "tip_rms_mm",
               "tip_max_mm", "thrust_rms_N", "torque_rms_Nm", "saturated_s", "joint_limit_excursion_deg",
               "singular_s", "nav_pos_rms_mm", "nav_att_rms_mrad")

#: The signals the metrics read (the others are not kept by the accumulator).
METRIC_SIGNALS = ("p_desired", "base_desired", "tip_desired", "joints_desired", "q_true", "tip_true",
                  "thrust_force", "thrust_saturated", "torques", "torques_applied", "singular_phase",
                  "nav_error_pos", "nav_error_att")


def _torques(s: Mapping[str, np.ndarray]):
    """The joint torques the motors applied (``torques_applied``), else (an older log) the commands."""
    tau = s.get("torques_applied")
    return tau if tau is not None and len(tau) else s.get("torques", ())


class RunMetrics:
    """The :data:`METRIC_KEYS` of one run, from its samples handed in by :meth:`add` in order.

    ``meta``: the run's ``T`` [s], ``joint_ranges`` (:func:`uvms_mj.sim.limits.plant_joint_ranges`)
    and, for a floating robot, ``robot`` (its ``layout``: ``base_qpos``, ``joint_qpos``).
    """

    def __init__(self, meta: Mapping[str, Any] | None = None) -> None:
        self.meta = dict(meta or {})
        self._done = 0  # samples in the partials
        self._pending: tuple[np.ndarray | None, dict[str, np.ndarray]] | None = None  # < BLOCK samples
        self._sum: dict[str, list[float]] = {}  # key -> [sum of squares, count]
        self._max: dict[str, float] = {}
        self._count: dict[str, int] = {}
        self._seen: set[str] = set()  # signals seen in some block
        self._robot: bool | None = None
        self._planar_full: bool | None = None
        self._excursion = joint_limit_excursion(np.empty((0, 0)), None)  # the largest so far (NaN: none)

    # -- input -----------------------------------------------------------------------------------
    def add(self, t: np.ndarray | None, signals: Mapping[str, np.ndarray]) -> None:
        """Samples that follow the ones added before: ``t`` (M,) [s] (None: unknown) and the
        run's signals (name -> (M, ...)); the metrics' signals only are kept until used (as
        copies: the caller may reuse its arrays)."""
        s = {k: np.asarray(v) for k, v in signals.items() if k in METRIC_SIGNALS and np.ndim(v) >= 1}
        t = None if t is None else np.asarray(t)
        m = {len(v) for v in s.values()} | ({len(t)} if t is not None else set())
        if not s or len(m) != 1:  # no metric signal, or signals of differing lengths (rows without some)
            self._flush(all_=True)
            if s:
                self._block(t, s)
            return
        if m.pop() == 0:
            return
        if self._pending is not None:
            pt, ps = self._pending
            if set(s) != set(ps):  # other signals from here on
                self._flush(all_=True)
            else:  # the samples left over (fewer than a block) and these
                t = None if pt is None or t is None else np.concatenate((pt, t))
                s = {k: np.concatenate((ps[k], v)) for k, v in s.items()}
        self._pending = (t, s)
        self._flush()

    def _flush(self, all_: bool = False) -> None:
        """Partials of the pending samples, a block of BLOCK samples aligned on the run's sample
        index at a time; the rest stays pending (a copy), unless ``all_``."""
        if self._pending is None:
            return
        t, s = self._pending
        n = len(next(iter(s.values())))
        i = 0
        while i < n:
            take = min(BLOCK - self._done % BLOCK, n - i)
            if take < BLOCK - self._done % BLOCK and not all_:
                break
            self._block(None if t is None else t[i:i + take], {k: v[i:i + take] for k, v in s.items()})
            self._done += take
            i += take
        self._pending = None if i == n else (None if t is None else t[i:].copy(),
                                             {k: v[i:].copy() for k, v in s.items()})

    # -- partials of one block -------------------------------------------------------------------
    def _ss(self, key: str, x: np.ndarray, count: int | None = None) -> None:
        a = self._sum.setdefault(key, [0.0, 0])
        a[0] += float(np.sum(np.square(x)))
        a[1] += int(np.size(x) if count is None else count)

    def _mx(self, key: str, x: np.ndarray) -> None:
        if np.size(x):
            v = float(np.max(x))
            old = self._max.get(key)
            self._max[key] = v if old is None or v > old or math.isnan(v) else old

    def _n(self, key: str, n: int) -> None:
        self._count[key] = self._count.get(key, 0) + int(n)

    def _block(self, t: np.ndarray | None, s: dict[str, np.ndarray]) -> None:
        self._seen.update(k for k, v in s.items() if len(v))
        meta = self.meta
        if self._robot is None:
            self._robot = bool("base_desired" in s or meta.get("robot"))
        q = s.get("q_true")
        if q is not None and len(q):
            e = joint_limit_excursion(q, meta.get("joint_ranges"), t)
            best = self._excursion["deg"]
            if math.isnan(best) or e["deg"] > best:
                self._excursion = e
        ph = s.get("singular_phase")
        if ph is not None and len(ph):
            self._n("singular", np.count_nonzero(ph != 0))
        for key, sig in (("nav_pos", "nav_error_pos"), ("nav_att", "nav_error_att")):
            e = s.get(sig)
            if e is not None and len(e):
                self._ss(key, e, count=len(e))  # RMS of the row norm: sum of squares over rows
        tau = _torques(s)
        if self._robot:
            self._robot_block(s, q, tau)
        else:
            self._planar_block(s, q, tau)

    def _planar_block(self, s, q, tau) -> None:
        full = all(k in s and len(s[k]) for k in ("p_desired", "q_true", "tip_true", "thrust_force", "torques"))
        if self._planar_full is None:
            self._planar_full = full
        thr = s.get("thrust_force")
        if thr is not None and len(thr):
            self._ss("thrust", thr)
            sat = s.get("thrust_saturated")
            self._n("saturated", np.count_nonzero(np.any(sat, axis=1)) if sat is not None and len(sat) else 0)
        if len(tau):
            self._ss("torque", tau)
        if full:
            pd = s["p_desired"]
            base = np.linalg.norm(pd[:, :2] - q[:, :2], axis=1)
            att = np.abs(pd[:, 2] - q[:, 2])
            tip = np.linalg.norm(pd[:, 3:5] - s["tip_true"], axis=1)
            for key, x in (("base", base), ("att", att), ("tip", tip)):
                self._ss(key, x)
                self._mx(key, x)

    def _robot_block(self, s, q, tau) -> None:
        if q is None or len(q) == 0:
            return
        layout = (self.meta.get("robot") or {}).get("layout") or {}
        a = int(layout.get("base_qpos", 0))
        bd = s.get("base_desired")
        if bd is not None and len(bd) == len(q):
            e = np.linalg.norm(bd[:, :3] - q[:, a:a + 3], axis=1)
            dots = np.abs(np.sum(bd[:, 3:7] * q[:, a + 3:a + 7], axis=1)
                          / (np.linalg.norm(bd[:, 3:7], axis=1) * np.linalg.norm(q[:, a + 3:a + 7], axis=1)))
            ang = 2.0 * np.arccos(np.clip(dots, 0.0, 1.0))
            for key, x in (("base", e), ("att", ang)):
                self._ss(key, x)
                self._mx(key, x)
        td, tip = s.get("tip_desired"), s.get("tip_true")
        if td is not None and tip is not None and len(td) == len(tip):
            e = np.linalg.norm(td - tip, axis=1)
            self._ss("tip", e)
            self._mx("tip", e)
        jd, jq = s.get("joints_desired"), layout.get("joint_qpos")
        if jd is not None and jq is not None and len(jd) == len(q) and jd.shape[1] == len(jq):
            self._ss("joint", jd - q[:, jq])
        if "thrust_force" in s:
            self._ss("thrust", s["thrust_force"])
        if len(tau):
            self._ss("torque", tau)
        sat = s.get("thrust_saturated")
        self._n("saturated", np.count_nonzero(np.any(sat, axis=1)) if sat is not None and len(sat) else 0)
        self._n("robot_samples", len(q))

    # -- output ----------------------------------------------------------------------------------
    @property
    def excursion(self) -> dict:
        """The largest joint-limit excursion of every sample added
        (:func:`uvms_mj.sim.limits.joint_limit_excursion`'s dict; deg NaN without samples or
        ranges). Reading it ends the input (the pending samples are summed): call it after the
        last :meth:`add`."""
        self._flush(all_=True)
        return self._excursion

    def _rms(self, key: str, scale: float = 1.0) -> float:
        a = self._sum.get(key)
        return scale * math.sqrt(a[0] / a[1]) if a and a[1] else math.nan

    def result(self) -> dict[str, float]:
        """The metrics of every sample added (:data:`METRIC_KEYS`; a floating robot's also
        ``joint_rms_mrad``)."""
        self._flush(all_=True)
        nan = math.nan
        robot = self._robot if self._robot is not None else bool(self.meta.get("robot"))
        T = float(self.meta.get("T", 0.02 if robot else 1 / 60))
        out = {k: nan for k in METRIC_KEYS}
        have = robot and self._count.get("robot_samples", 0) > 0
        full = not robot and bool(self._planar_full)
        if have or full:
            for key, name in (("base", "base_pos"), ("tip", "tip")):
                if key in self._sum:
                    out[f"{name}_rms_mm"] = self._rms(key, 1e3)
                    out[f"{name}_max_mm"] = 1e3 * self._max[key]
            if "att" in self._sum:
                out["base_att_rms_mrad"] = self._rms("att", 1e3)
                out["base_att_max_mrad"] = 1e3 * self._max["att"]
        if have or not robot:
            out["thrust_rms_N"] = self._rms("thrust")
            out["torque_rms_Nm"] = self._rms("torque")
            if have or "thrust" in self._sum:
                n = self._count.get("saturated", 0) if "thrust_saturated" in self._seen else 0
                out["saturated_s"] = float(n * T)
        out["joint_limit_excursion_deg"] = self._excursion["deg"]
        if "singular" in self._count:  # Eq. 12's phase logged for at least one sample
            out["singular_s"] = float(self._count["singular"] * float(self.meta.get("T", 1 / 60)))
        out["nav_pos_rms_mm"] = self._rms("nav_pos", 1e3)
        out["nav_att_rms_mrad"] = self._rms("nav_att", 1e3)
        if robot:
            out["joint_rms_mrad"] = self._rms("joint", 1e3) if have else nan
        return out


def metrics(result) -> dict[str, float]:
    """The :data:`METRIC_KEYS` of a run (a :class:`~uvms_mj.sim.loop.RunResult`, or a log read
    back: anything with ``t``, ``signals`` and ``meta``), :class:`RunMetrics` over its samples;
    a run streamed without keeping its signals gives the metrics it accumulated
    (``result.metrics``). NaN where the run has no sample with the signals; never raises for a
    short or broken run."""
    done = getattr(result, "metrics", None)
    if isinstance(done, Mapping):
        return dict(done)
    acc = RunMetrics(getattr(result, "meta", None))
    acc.add(getattr(result, "t", None), result.signals)
    return acc.result()
