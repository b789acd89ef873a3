"""The controller interface and registry.

A controller is a small object with ``reset(measurement)`` and ``compute(measurement) ->
Command``, created by name from a registry. Third-party packages add controllers through the
``uvms_mj.controllers`` entry-point group (the entry point names a class or factory taking the
same keyword arguments as the built-ins)::

    [project.entry-points."uvms_mj.controllers"]
    my_ctrl = "my_package.module:MyController"

Controllers see only :class:`Measurement` objects and their own nominal model
(:class:`~uvms_mj.control.nominal.NominalRobot`); never MuJoCo's state or parameters.
"""

from __future__ import annotations

import abc
import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

ENTRY_POINT_GROUP = "uvms_mj.controllers"


@dataclass(frozen=True)
class Measurement:
    """What the controller receives at sample k (time t = k T).

    Attributes:
        k: sample index.
        t: time [s].
        q: measured generalized coordinates (p0x, p0y, phi0, phi1, phi2) [m, m, rad, rad, rad]
            (world frame for the base), after the sensor model (noise, quantization, delay).
        qd: measured generalized velocities, or None when there is no velocity sensor (the
            controller then differentiates positions).
    """

    k: int
    t: float
    q: np.ndarray
    qd: np.ndarray | None = None


@dataclass
class Command:
    """The controller's output for one sample, held constant until the next (zero-order hold).

    Attributes:
        thrust: thruster commands [N] (within their limits).
        torques: joint torques (tau1, tau2) [N m].
        signals: per-sample internal signals for logging (name -> float or 1-D array).
    """

    thrust: np.ndarray
    torques: np.ndarray
    signals: dict[str, Any] = field(default_factory=dict)


class Controller(abc.ABC):
    """Interface of every controller."""

    #: registry name (set by :func:`register`)
    name: str = ""

    @abc.abstractmethod
    def reset(self, measurement: Measurement) -> None:
        """Start a run from the first measurement (sample 0)."""

    @abc.abstractmethod
    def compute(self, measurement: Measurement) -> Command:
        """Command for sample k."""


class ControllerError(ValueError):
    """Bad controller name or parameter; the message names it and what is allowed."""


_REGISTRY: dict[str, Callable[..., Controller]] = {}


def register(name: str) -> Callable:
    """Class decorator: make a controller available under ``name``."""

    def deco(factory):
        _REGISTRY[name] = factory
        try:
            factory.name = name
        except (AttributeError, TypeError):
            pass
        return factory

    return deco


# ------------------------------------------------------------------ parameter checks


def check_gains(name: str, values: Any, size: int = 5) -> np.ndarray:
    """Gains must be `size` numbers strictly inside (0, 1) (digital RAC convergence, Eqs. 10-11)."""
    arr = np.atleast_1d(np.asarray(values, dtype=float))
    if arr.size == 1:
        arr = np.full(size, float(arr[0]))
    if arr.shape != (size,):
        raise ControllerError(f"{name} = {values!r} must be 1 or {size} numbers")
    for i, v in enumerate(arr):
        if not (0.0 < v < 1.0):
            raise ControllerError(f"{name}[{i}] = {float(v)!r} is outside the allowed range (0, 1)")
    return arr


def check_positive(name: str, value: Any) -> float:
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise ControllerError(f"{name} = {value!r} must be finite and > 0")
    return v
