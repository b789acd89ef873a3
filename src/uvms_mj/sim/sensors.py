"""Per-signal sensors: each measured signal with its own noise, bias, quantization, rate and delay.

The signals of a robot's state (for the paper's planar base: position (p0x, p0y) world [m],
attitude phi0 [rad], joints (phi1, phi2) [rad]; for a free vehicle: position (x, y, z) world
[m], attitude (the orientation quaternion: noise and bias as a BODY-frame rotation vector
[rad] composed with the true one, q_meas = q_true * exp(b) * exp(n)), joints [rad]; for every
robot: velocity, the whole qvel, given to the controller only when this signal is configured).

A signal sampled at ``rate`` [Hz] refreshes every ``every = 1 / (rate T)`` control samples
(a whole number) and holds its value in between (zero-order hold); its value at a refresh at
sample r is the true state of sample ``r - delay`` (at least sample 0) plus ``bias`` plus
Gaussian noise of std ``noise`` (drawn at the refresh, from the signal's own random stream:
``numpy.random.default_rng([seed, i])``, i its index in :data:`SIGNALS`), then quantized to
``quantum`` (position, joints, velocity; not the quaternion). Everything is off by default.

This is the model a scenario's ``sensors: {position: {...}, attitude: {...}, ...}`` sections
build; the flat fields of :class:`uvms_mj.sim.loop.SensorModel` (``position_noise``,
``delay`` 0 or 1...) remain the paper reproduction's model, unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from uvms_mj.rotations import quat_from_rotvec, quat_mul

__all__ = ["SIGNALS", "Signal", "SignalSensors", "samples_of"]

#: The signals, in the order of their random streams.
SIGNALS = ("position", "attitude", "joints", "velocity")


@dataclass(frozen=True)
class Signal:
    """One signal's sensor (module docstring).

    Attributes:
        noise: std of the Gaussian noise (the signal's units; attitude: rad per body axis).
        bias: a constant offset: one number (every component) or one per component; () none.
        quantum: quantization step (0: none).
        rate: refresh rate [Hz]; None: every control sample.
        delay: delay in control samples (an int), or None.
        delay_s: delay in seconds (a whole number of control periods), or None.
    """

    noise: float = 0.0
    bias: Sequence[float] = ()
    quantum: float = 0.0
    rate: float | None = None
    delay: int | None = None
    delay_s: float | None = None

    def __post_init__(self) -> None:
        for name in ("noise", "quantum"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} = {v!r} must be finite and >= 0")
        b = tuple(float(x) for x in np.atleast_1d(np.asarray(self.bias, dtype=float)))
        if not all(map(math.isfinite, b)):
            raise ValueError(f"bias = {self.bias!r} must be finite")
        object.__setattr__(self, "bias", b)
        if self.rate is not None and not (math.isfinite(self.rate) and self.rate > 0):
            raise ValueError(f"rate = {self.rate!r} Hz must be finite and > 0")
        if self.delay is not None and self.delay_s is not None:
            raise ValueError("give the delay in samples (delay) or in seconds (delay_s), not both")
        if self.delay is not None and not (isinstance(self.delay, int) and self.delay >= 0):
            raise ValueError(f"delay = {self.delay!r} must be a whole number of samples >= 0")
        if self.delay_s is not None and not (math.isfinite(self.delay_s) and self.delay_s >= 0):
            raise ValueError(f"delay_s = {self.delay_s!r} s must be finite and >= 0")


def samples_of(signal: Signal, T: float) -> tuple[int, int]:
    """(every, delay) of a signal in control samples of period ``T`` [s].

    Raises:
        ValueError: a rate whose period is not a whole number (>= 1) of control periods, a
            delay_s that is not a whole number of control periods; the message says which."""
    every = 1
    if signal.rate is not None:
        x = 1.0 / (signal.rate * T)
        every = round(x)
        if every < 1 or abs(x - every) > 1e-9 * max(1.0, x):
            raise ValueError(f"rate = {signal.rate:g} Hz: its period must be a whole number of control periods "
                             f"T = {T:g} s (rates allowed: {1 / T:g} Hz / n)")
    delay = signal.delay or 0
    if signal.delay_s is not None:
        x = signal.delay_s / T
        delay = round(x)
        if abs(x - delay) > 1e-9 * max(1.0, x):
            raise ValueError(f"delay_s = {signal.delay_s:g} s must be a whole number of control periods T = {T:g} s")
    return int(every), int(delay)


class SignalSensors:
    """The per-signal measurement of one run (module docstring).

    Args:
        signals: signal name -> :class:`Signal` (a subset of :data:`SIGNALS`).
        T: the control period [s].
        seed: the run's seed.
        layout: the robot's :class:`~uvms_mj.plant.layout.Layout`.
    """

    def __init__(self, signals: Mapping[str, Signal], T: float, seed: int, layout) -> None:
        unknown = set(signals) - set(SIGNALS)
        if unknown:
            raise ValueError(f"sensor signals {sorted(unknown)}: allowed {', '.join(SIGNALS)}")
        self.signals = dict(signals)
        self.steps = {name: samples_of(s, T) for name, s in self.signals.items()}
        self.rngs = {name: np.random.default_rng([int(seed), i]) for i, name in enumerate(SIGNALS)}
        self.free = bool(layout.base_free)
        a = layout.base_qadr
        if self.free:
            self.index = {"position": np.arange(a, a + 3), "attitude": np.arange(a + 3, a + 7),
                          "joints": np.asarray(layout.joint_qadr, dtype=int)}
        else:
            nb = int(layout.base_dofs.size)
            hinge = [i for i in range(a, a + nb) if layout.base_hinge >= 0 and i == a + nb - 1]
            slides = [i for i in range(a, a + nb) if i not in hinge]
            self.index = {"position": np.array(slides, dtype=int), "attitude": np.array(hinge, dtype=int),
                          "joints": np.asarray(layout.joint_qadr, dtype=int)}
        #: the true states of the last samples a refresh may read (sample index -> (q, qd))
        self.history: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self.window = max([e + d for e, d in self.steps.values()] or [1])
        self.held: dict[str, tuple[int, np.ndarray]] = {}

    def _value(self, name: str, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        s, rng = self.signals[name], self.rngs[name]
        if name == "velocity":
            x = qd.copy()
        else:
            x = q[self.index[name]].copy()
        if name == "attitude" and self.free:  # q_true * exp(bias) * exp(noise), body frame
            if s.bias:
                x = quat_mul(x, quat_from_rotvec(np.resize(np.asarray(s.bias), 3)))
            if s.noise:
                x = quat_mul(x, quat_from_rotvec(rng.normal(0.0, s.noise, 3)))
            return x / np.linalg.norm(x)
        if s.bias:
            x = x + np.resize(np.asarray(s.bias), x.size)
        if s.noise and x.size:
            x = x + rng.normal(0.0, s.noise, x.size)
        if s.quantum:
            x = np.round(x / s.quantum) * s.quantum
        return x

    def measure(self, k: int, q_true: np.ndarray, qd_true: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """(qpos, qvel or None) as measured at control sample k (called once per sample, in order)."""
        self.history[k] = (np.array(q_true, dtype=float), np.array(qd_true, dtype=float))
        self.history.pop(k - self.window - 1, None)  # older than any refresh can reach
        q = np.array(q_true, dtype=float)
        qd = None
        for name in SIGNALS:
            if name not in self.signals:
                continue
            every, delay = self.steps[name]
            r = (k // every) * every
            held = self.held.get(name)
            if held is None or held[0] != r:
                qj, qdj = self.history[max(0, r - delay)]  # r > k - every: within the window
                held = self.held[name] = (r, self._value(name, qj, qdj))
            if name == "velocity":
                qd = held[1].copy()
            else:
                q[self.index[name]] = held[1]
        return q, qd
