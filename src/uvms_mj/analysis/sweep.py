"""Parameter sweeps: many runs of one scenario over sampled parameters, in parallel, resumable.

``uvms-mj sweep SCENARIO --vary KEY.PATH=SPEC ... [--n N] [--controllers rac,rac_dob]`` runs
the scenario once per sample and controller and writes a results table and summary figures.
Library use::

    plan = plan_sweep("scenarios/paper.yaml", ["plant.current[0]=uniform(0, 0.1)"], n=50)
    outcome = run_sweep(plan, "logs/paper-sweep", workers=2)
    outcome.rows, outcome.summary, outcome.figures

Keys
----
``KEY.PATH`` is any scenario field (:mod:`uvms_mj.scenario.schema`), checked against the schema before
anything runs: ``plant.current``, ``thrusters.tau``, ``sensors.position_noise``,
``controller.params.gamma``, ``trajectory.cruise_speed``, ... Inside ``plant.overrides`` and
``nominal.overrides`` the rest of the path is one parameter name (``OVERRIDE_KEYS``, e.g.
``nominal.overrides.base.added_mass``); inside ``controller.params`` a parameter of every swept
controller. Not allowed: ``name``, ``description``, ``seed`` (per-run seeds come from
``--seed``), ``controller.name`` (use ``--controllers``) and ``outputs.*`` (the sweep writes
its own).

* ``KEY[i]`` is component i of a vector field (``plant.current[0]``: the current along world
  X); the other components keep the scenario's value.
* ``{a,b,...}`` in a key names several fields that all take the SAME drawn value (one axis):
  ``nominal.overrides.{base,link1,link2}.added_mass=scale(uniform(0.7, 1.3))`` scales the added
  mass of every body by one factor. Quote such an argument in the shell (bash expands braces).

Specs
-----
==================================  ==========================================================
``[a, b, c]``                       grid: these values (YAML; a vector field needs a list per
                                    value, ``plant.current=[[0, 0], [0.1, 0]]``)
``linspace(start, stop, n)``        grid: n evenly spaced values, both ends included
``uniform(low, high)``              random: uniform in [low, high), low < high
``loguniform(low, high)``           random: log-uniform, 0 < low < high
``normal(mean, std)``               random: Gaussian, std > 0 (no truncation: a draw outside
                                    the field's allowed values is an error before any run)
``choice(a, b, ...)``               random: one of the values, equally likely
``scale(SPEC)``                     a factor (grid or random) on the scenario's value of the
                                    field: ``scale(uniform(0.7, 1.3))``; on a vector, every
                                    component by the same factor
``[SPEC_or_value, ...]``            a vector field per component: ``plant.current=[uniform(0,
                                    0.1), 0]``; each component spec is its own axis
``value``                           a single value (a one-point grid; same as ``--set``)
==================================  ==========================================================

Values are YAML scalars (numbers, ``true``/``false``, ``null``, strings; ``on``, ``off``,
``yes``, ``no`` stay strings, e.g. ``plant.hydro.drag=choice(strip, mujoco, off)``); quote a
string that contains a comma or a bracket.

"The scenario's value" for ``scale`` (and the untouched components of ``KEY[i]``) is the value
the run would have without the sweep: the scenario file plus ``--set``, with defaults filled
in (``uvms_mj.scenario.schema.resolved``); for a parameter override not given in the file it is the
model's value: for ``nominal.overrides.*`` the robot model file (what the controller would
use), for ``plant.overrides.*`` the plant's (model file plus the truth differences of
``plant.model_mismatch``). Each column of the results table holds the DRAWN value: the factor
for ``scale`` (column ``scale(KEY)``), the component for ``KEY[i]``.

Samples
-------
Every grid spec is an axis of a Cartesian product (in the order given; the last one varies
fastest); every random spec is drawn independently. The sweep has
``product(grid sizes) x N`` samples: at each grid point, ``N = --n`` samples with fresh random
draws (and fresh simulation seeds). So: grids only, no ``--n``: one run per grid point;
grids only with ``--n 5``: each grid point repeated 5 times with different seeds (matters with
sensor noise); random only: ``--n`` samples (``--n`` is then required); both: ``--n`` random
draws at each grid point.

Reproducibility: sample i (0-based, grid point g, repeat r: i = g * N + r) uses
``SeedSequence(seed).spawn(...)[i]``, spawned again into two: the first draws the sample's
random parameters (in the order of the ``--vary`` options), the second gives the run's
``seed`` (sensor noise). The same arguments give the same parameters and seeds. With several
``--controllers``, every sample is run with each of them (same parameters, same seed): the
pairs give the paired ratio (e.g. rac_dob / rac) of each metric.

Outputs (in ``--out-dir DIR``)
--------------------------
* ``sweep.json``: the sweep definition (base scenario, specs, n, seed, controllers);
* ``runs.jsonl``: one line per finished run, appended as runs finish (the resume record);
* ``results.csv`` (and ``results.parquet`` when pyarrow is installed): one row per run:
  ``run_id, sample, controller, seed``, one column per axis, every metric of
  :func:`uvms_mj.sim.experiment.metrics`, ``status`` (ok | diverged | error | crashed), ``reason``,
  ``t_end`` (simulated time reached), ``wall_s``, ``log`` (MCAP path with ``--logs``, else
  empty), ``values`` (JSON: the value each varied field got), ``sets`` (JSON: the ``--set``
  arguments that reproduce the run with ``uvms-mj run SCENARIO``), ``key``;
* ``summary.json``: per controller the counts and the median and 10-90 % range of each
  metric; per controller pair the paired ratio's median and 10-90 % range;
* ``sweep_metrics.png``: base position, attitude and tip RMS against each axis, per
  controller, and their distributions; ``sweep_ratio.png`` (two or more controllers): the
  paired ratio (each controller / the first) against each axis, and its distribution;
* ``logs/<run_id>.mcap`` with ``--logs`` (about 1.8 MB and +50 % run time per 40 s run).

Metrics of a diverged run cover the time until it stopped; they are in the table but left out
of the distributions and ratios (the figures mark failed runs with crosses).

Resume: ``run_id`` is ``s<sample>-<controller>``; ``key`` is a hash of the run's resolved
scenario (every parameter, the controller and the seed). A rerun with the same arguments skips
every run whose key is in ``runs.jsonl`` (whatever its status, except ``crashed``: a worker
process that died is retried). A different definition (scenario content, specs, ``--n``,
``--seed``, controllers) in the same DIR is refused with what differs; ``fresh=True``
(``--fresh``) deletes the old results first. ``workers``, ``engine`` and ``logs`` may change.

Failures: a run that diverges is recorded with status ``diverged`` and its reason; one that
raises, with ``error`` and the exception; a worker process that dies (e.g. a crash in native
code) is retried up to twice in a fresh pool, then recorded as ``crashed``. None stops the
sweep.

Engines: ``process`` (default): a local ``ProcessPoolExecutor`` with the ``spawn`` start
method (no fork of a process holding MuJoCo state and ctypes callbacks); ``ray``: Ray tasks
(``pip install 'uvms-mj[ray]'``; imported only then; uses the cluster of ``RAY_ADDRESS`` if
set or an already initialised Ray, else starts a local one with ``workers`` CPUs); ``serial``:
in this process (debugging). Each run builds its own plant; the native hydrodynamics are
compiled once into the cache before the workers start.
"""

from __future__ import annotations

import copy
import csv
import difflib
import hashlib
import itertools
import json
import math
import os
import re
import shutil
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from pydantic import BaseModel

__all__ = [
    "RAY_MISSING",
    "SweepError",
    "SweepOutcome",
    "SweepPlan",
    "format_summary",
    "parse_spec",
    "parse_vary",
    "plan_sweep",
    "plot_sweep",
    "read_results",
    "run_sweep",
    "sample_parameters",
    "summarize",
]

#: The metrics of :func:`uvms_mj.sim.experiment.metrics`, in table order (others found are appended).
METRICS = ("base_pos_rms_mm", "base_pos_max_mm", "base_att_rms_mrad", "base_att_max_mrad", "tip_rms_mm",
           "tip_max_mm", "thrust_rms_N", "torque_rms_Nm", "saturated_s")
#: The metrics of the summary figures and ratios.
SUMMARY_METRICS = {"base_pos_rms_mm": "base position RMS [mm]", "base_att_rms_mrad": "base attitude RMS [mrad]",
                   "tip_rms_mm": "end tip RMS [mm]"}
FINISHED = ("ok", "diverged", "error")
ENGINES = ("process", "ray", "serial")
RAY_MISSING = ("--engine ray needs Ray, which is not installed: pip install 'uvms-mj[ray]' "
               "(or pip install ray); the default --engine process needs nothing more")
MAX_ATTEMPTS = 3
FORMAT = 1
#: Largest linspace(...) count and largest number of runs in one sweep (checked before anything
#: is allocated or run).
MAX_GRID = 10_000
MAX_RUNS = 100_000


class SweepError(ValueError):
    """Bad sweep input (spec, key, range, controller, engine, out folder): the message names it."""


# ============================================================================ specs

_FUNCS = {
    "linspace": "linspace(start, stop, n)",
    "uniform": "uniform(low, high)",
    "loguniform": "loguniform(low, high)",
    "normal": "normal(mean, std)",
    "choice": "choice(a, b, ...)",
    "scale": "scale(SPEC)",
}
SPEC_HELP = ("[a, b, ...], linspace(start, stop, n), uniform(low, high), loguniform(low, high), normal(mean, std), "
             "choice(a, b, ...), scale(SPEC), [SPEC or value, ...] per component, or a single value")


def _fmt(v: Any) -> str:
    """A value as in a spec (JSON-like, floats shortest repr)."""
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, bool) or v is None:
        return json.dumps(v)
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return str(v)


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))


@dataclass(frozen=True)
class Grid:
    """Fixed values (one axis of the Cartesian product)."""

    values: tuple
    source: str = ""  # "linspace(...)" when written so

    kind = "grid"

    def __str__(self) -> str:
        return self.source or "[" + ", ".join(_fmt(v) for v in self.values) + "]"


@dataclass(frozen=True)
class Random:
    """A distribution, drawn once per sample."""

    dist: str  # uniform | loguniform | normal | choice
    args: tuple

    kind = "random"

    def draw(self, rng: np.random.Generator) -> Any:
        if self.dist == "uniform":
            return float(rng.uniform(self.args[0], self.args[1]))
        if self.dist == "loguniform":
            return float(math.exp(rng.uniform(math.log(self.args[0]), math.log(self.args[1]))))
        if self.dist == "normal":
            return float(rng.normal(self.args[0], self.args[1]))
        return copy.deepcopy(self.args[int(rng.integers(len(self.args)))])

    def __str__(self) -> str:
        return f"{self.dist}(" + ", ".join(_fmt(v) for v in self.args) + ")"


@dataclass(frozen=True)
class Scale:
    """A factor (grid or random) on the scenario's value of the field."""

    inner: Grid | Random

    @property
    def kind(self) -> str:
        return self.inner.kind

    def __str__(self) -> str:
        return f"scale({self.inner})"


@dataclass(frozen=True)
class Vector:
    """A vector field given per component: each item a constant or a Grid/Random/Scale."""

    items: tuple

    def __str__(self) -> str:
        return "[" + ", ".join(str(x) if isinstance(x, (Grid, Random, Scale)) else _fmt(x) for x in self.items) + "]"


Spec = Grid | Random | Scale | Vector


class _SpecSyntax(Exception):
    """A spec error; ``syntax`` errors get the list of spec forms appended."""

    def __init__(self, msg: str, syntax: bool = False) -> None:
        super().__init__(msg)
        self.syntax = syntax


_NONFINITE = {"inf": math.inf, "+inf": math.inf, "-inf": -math.inf, "infinity": math.inf, "+infinity": math.inf,
              "-infinity": -math.inf, ".inf": math.inf, "+.inf": math.inf, "-.inf": -math.inf, "nan": math.nan,
              ".nan": math.nan}


def _atom(text: str) -> Any:
    """A plain value, parsed as YAML, except that only true/false are booleans (PyYAML's YAML 1.1
    also reads on/off/yes/no as booleans: here they stay strings, e.g. plant.hydro.drag's off)."""
    low = text.strip().lower()
    if low in _NONFINITE:
        return _NONFINITE[low]
    if low in ("on", "off", "yes", "no", "y", "n"):
        return text.strip()
    from uvms_mj.scenario.schema import _Loader

    try:
        return yaml.load(text, Loader=_Loader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError:
        return text.strip()


def _tokenize(text: str) -> list[tuple[str, Any, int]]:
    toks, i = [], 0
    while i < len(text):
        c = text[i]
        if c.isspace():
            i += 1
        elif c in "()[],":
            toks.append((c, c, i))
            i += 1
        elif c in "\"'":
            j = text.find(c, i + 1)
            if j < 0:
                raise _SpecSyntax(f"unterminated quote at character {i + 1}", syntax=True)
            toks.append(("str", text[i + 1:j], i))
            i = j + 1
        else:
            j = i
            while j < len(text) and text[j] not in "()[],\"'":
                j += 1
            toks.append(("atom", text[i:j].strip(), i))
            i = j
    return toks


def _parse_tree(text: str):
    """Text -> nested ("call", name, args) | ("list", items) | ("const", value) nodes."""
    toks = _tokenize(text)
    pos = 0

    def peek(k: int = 0):
        return toks[pos + k] if pos + k < len(toks) else ("end", None, len(text))

    def take(kind: str):
        nonlocal pos
        t = peek()
        if t[0] != kind:
            got = "the end" if t[0] == "end" else repr(t[1])
            raise _SpecSyntax(f"expected {kind!r} at character {t[2] + 1}, got {got}", syntax=True)
        pos += 1
        return t

    def items(close: str) -> list:
        out = []
        if peek()[0] == close:
            take(close)
            return out
        while True:
            out.append(expr())
            t = peek()
            if t[0] == ",":
                take(",")
                continue
            take(close)
            return out

    def expr():
        nonlocal pos
        t = peek()
        if t[0] == "atom" and peek(1)[0] == "(":
            name = t[1]
            if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
                raise _SpecSyntax(f"{name!r} is not a function name", syntax=True)
            pos += 2
            return ("call", name, items(")"))
        if t[0] == "[":
            pos += 1
            return ("list", items("]"))
        if t[0] == "atom":
            pos += 1
            if not t[1]:
                raise _SpecSyntax(f"missing value at character {t[2] + 1}", syntax=True)
            return ("const", _atom(t[1]))
        if t[0] == "str":
            pos += 1
            return ("const", t[1])
        got = "the end" if t[0] == "end" else repr(t[1])
        raise _SpecSyntax(f"expected a value, a list or a function call at character {t[2] + 1}, got {got}",
                          syntax=True)

    if not text.strip():
        raise _SpecSyntax("empty spec", syntax=True)
    node = expr()
    if pos != len(toks):
        t = toks[pos]
        raise _SpecSyntax(f"unexpected {t[1]!r} at character {t[2] + 1}", syntax=True)
    return node


def _has_call(node) -> bool:
    return node[0] == "call" or (node[0] == "list" and any(_has_call(x) for x in node[1]))


def _const(node) -> Any:
    if node[0] == "const":
        return node[1]
    if node[0] == "list":
        return [_const(x) for x in node[1]]
    raise _SpecSyntax(f"{node[1]}(...) is not allowed inside a value")


def _check_finite(value: Any, what: str) -> None:
    if isinstance(value, (list, tuple)):
        for v in value:
            _check_finite(v, what)
    elif _is_num(value) and not math.isfinite(float(value)):
        raise _SpecSyntax(f"{what} must be finite (got {value!r})")


def _number(node, what: str) -> float:
    if node[0] != "const" or not _is_num(node[1]):
        shown = _const(node) if not _has_call(node) else f"{node[1]}(...)"
        raise _SpecSyntax(f"{what} must be a number (got {shown!r})")
    v = float(node[1])
    if not math.isfinite(v):
        raise _SpecSyntax(f"{what} must be finite (got {node[1]!r})")
    return v


def _call(node) -> Grid | Random | Scale:
    _, name, args = node
    if name not in _FUNCS:
        close = difflib.get_close_matches(name, list(_FUNCS), n=1, cutoff=0.6)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise _SpecSyntax(f"unknown function {name!r}{hint}", syntax=True)
    sig = _FUNCS[name]
    fixed = {"linspace": 3, "uniform": 2, "loguniform": 2, "normal": 2, "scale": 1}
    if name in fixed and len(args) != fixed[name]:
        raise _SpecSyntax(f"{sig} takes {fixed[name]} argument(s), got {len(args)}")
    if name == "linspace":
        a, b = _number(args[0], f"{sig}: start"), _number(args[1], f"{sig}: stop")
        nn = args[2]
        whole = nn[0] == "const" and _is_num(nn[1]) and math.isfinite(float(nn[1])) and float(nn[1]) == int(nn[1])
        if not whole:
            shown = _const(nn) if not _has_call(nn) else f"{nn[1]}(...)"
            raise _SpecSyntax(f"{sig}: n must be a whole number (got {shown!r})")
        n = int(nn[1])
        if n < 1:
            raise _SpecSyntax(f"{sig}: empty range: n must be >= 1 (got {n})")
        if n > MAX_GRID:
            raise _SpecSyntax(f"{sig}: n = {n} values is too many; at most {MAX_GRID}")
        if n > 1 and a == b:
            raise _SpecSyntax(f"{sig}: empty range: start == stop == {a!r} (use a single value)")
        return Grid(tuple(float(v) for v in np.linspace(a, b, n)), source=f"linspace({a!r}, {b!r}, {n})")
    if name in ("uniform", "loguniform"):
        lo, hi = _number(args[0], f"{sig}: low"), _number(args[1], f"{sig}: high")
        if not lo < hi:
            raise _SpecSyntax(f"{sig}: empty range: low must be < high (got low={lo!r}, high={hi!r})")
        if name == "loguniform" and lo <= 0:
            raise _SpecSyntax(f"{sig}: low must be > 0 (got {lo!r})")
        return Random(name, (lo, hi))
    if name == "normal":
        mu, sd = _number(args[0], f"{sig}: mean"), _number(args[1], f"{sig}: std")
        if not sd > 0:
            raise _SpecSyntax(f"{sig}: std must be > 0 (got {sd!r})")
        return Random("normal", (mu, sd))
    if name == "choice":
        if not args:
            raise _SpecSyntax(f"{sig}: empty: give at least one value")
        vals = tuple(_const(a) for a in args)
        _check_finite(vals, f"{sig}: the values")
        return Random("choice", vals)
    # scale
    inner = _interpret(args[0], top=False)
    if not isinstance(inner, (Grid, Random)):
        raise _SpecSyntax("scale(SPEC): SPEC must be a grid or a distribution of factors, "
                          "e.g. scale(uniform(0.7, 1.3))")
    values = inner.values if isinstance(inner, Grid) else (inner.args if inner.dist == "choice" else ())
    if any(not _is_num(v) for v in values):
        raise _SpecSyntax(f"scale(SPEC): the factors must be numbers (got {_fmt(list(values))})")
    return Scale(inner)


def _interpret(node, top: bool = True) -> Spec:
    if node[0] == "call":
        return _call(node)
    if node[0] == "const":
        _check_finite(node[1], "the value")
        return Grid((node[1],))
    items = node[1]
    if any(x[0] == "call" for x in items):
        if not top:
            raise _SpecSyntax("a per-component list [SPEC, ...] is only allowed at the top of a spec")
        out = []
        for x in items:
            if x[0] == "call":
                out.append(_call(x))
            elif _has_call(x):
                raise _SpecSyntax("a component of [SPEC, ...] must be a value or one spec, not a list of specs")
            else:
                v = _const(x)
                _check_finite(v, "a component")
                out.append(v)
        return Vector(tuple(out))
    if any(_has_call(x) for x in items):
        raise _SpecSyntax("a grid's values must be plain values (functions are allowed only as the components of a "
                          "per-component list, e.g. [uniform(0, 0.1), 0])")
    if not items:
        raise _SpecSyntax("empty grid []: give at least one value")
    vals = tuple(_const(x) for x in items)
    _check_finite(vals, "grid values")
    return Grid(vals)


def parse_spec(text: str) -> Spec:
    """Parse a SPEC (see the module docstring). Raises SweepError with the reason."""
    try:
        return _interpret(_parse_tree(str(text)))
    except _SpecSyntax as exc:
        raise SweepError(f"spec {text!r}: {exc}" + (f"; specs: {SPEC_HELP}" if exc.syntax else "")) from None


# ============================================================================ keys

@dataclass(frozen=True)
class Axis:
    """One dimension of the sweep: a grid or a random spec, with its table column."""

    column: str
    spec: Grid | Random
    scale: bool = False

    @property
    def kind(self) -> str:
        return self.spec.kind


@dataclass(frozen=True)
class Assignment:
    """What one --vary does to one component (or the whole) of its fields."""

    paths: tuple[str, ...]  # dotted field paths ("plant.current", "nominal.overrides.base.added_mass")
    index: int | None  # component, or None: the whole field
    column: str | None  # the axis drawn, or None: a constant
    value: Any = None  # the constant
    scale: bool = False


@dataclass(frozen=True)
class Vary:
    """A parsed ``KEY.PATH=SPEC``."""

    text: str
    key: str  # as written (braces kept), without the index
    index: int | None
    spec: Spec
    axes: tuple[Axis, ...]
    assignments: tuple[Assignment, ...]

    def __str__(self) -> str:
        return f"{self.key}{'' if self.index is None else f'[{self.index}]'}={self.spec}"


_FORBIDDEN = {
    "name": "the sweep keeps the scenario's name",
    "description": "the sweep keeps the scenario's description",
    "seed": "per-run seeds are derived from --seed and the sample index",
    "controller.name": "choose the controllers with --controllers",
    "outputs": "the sweep writes its own outputs (--logs, --out-dir)",
}


def _expand(key: str) -> list[str]:
    m = re.search(r"\{([^{}]*)\}", key)
    if not m:
        if "{" in key or "}" in key:
            raise SweepError(f"key {key!r}: unbalanced braces (write {{a,b}} to name several fields)")
        return [key]
    opts = [o.strip() for o in m.group(1).split(",")]
    if any(not o for o in opts) or len(opts) < 1:
        raise SweepError(f"key {key!r}: empty alternative in {{...}}")
    out = []
    for o in opts:
        out.extend(_expand(key[:m.start()] + o + key[m.end():]))
    return out


def _check_path(path: str, controllers: Sequence[str], item: str) -> None:
    """The dotted path names a scenario field (schema walk; overrides and controller params
    checked by name). Raises SweepError naming it."""
    from uvms_mj.control import available
    from uvms_mj.plant.params import HYDRO_BODIES, OVERRIDE_KEYS
    from uvms_mj.scenario.schema import OVERRIDE_NAMES, Scenario, _controller_signature

    pre = f"--vary {item!r}: "
    parts = path.split(".")
    if any(not p for p in parts):
        raise SweepError(pre + f"{path!r} is not a key path (KEY.PATH, e.g. plant.current)")
    for bad, why in _FORBIDDEN.items():
        if path == bad or path.startswith(bad + "."):
            raise SweepError(pre + f"{bad} cannot be varied: {why}")
    model: Any = Scenario
    loc: list[str] = []
    for i, part in enumerate(parts):
        fields = model.model_fields
        if part not in fields:
            close = difflib.get_close_matches(part, list(fields), n=1, cutoff=0.6)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            where = ".".join(loc) or "the scenario"
            raise SweepError(pre + f"{'.'.join(loc + [part])}: unknown key {part!r} in {where}{hint}; allowed: "
                             + ", ".join(fields))
        loc.append(part)
        rest = parts[i + 1:]
        if tuple(loc) in (("plant", "overrides"), ("nominal", "overrides")):
            name = ".".join(rest)
            allowed = ", ".join(k.replace("BODY", "{" + ",".join(HYDRO_BODIES) + "}") for k in OVERRIDE_KEYS)
            if not name or name not in OVERRIDE_NAMES:
                close = difflib.get_close_matches(name, list(OVERRIDE_NAMES), n=1, cutoff=0.6)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise SweepError(pre + f"{path}: unknown parameter {name!r}{hint}; allowed after "
                                 f"{'.'.join(loc)}.: {allowed}")
            if loc[0] == "plant" and name.startswith("thrusters."):
                fld = name.partition(".")[2]
                raise SweepError(pre + f"{path}: vary the plant's thrusters in the thrusters section "
                                 f"(thrusters.{'dead_zone_band' if fld == 'dead_zone' else fld})")
            return
        if tuple(loc) == ("controller", "params"):
            if len(rest) != 1:
                raise SweepError(pre + f"{path}: expected controller.params.NAME (one parameter name)")
            for c in controllers:
                if c not in available():
                    continue  # reported by the controller check
                named, var_kw = _controller_signature(c)
                if rest[0] not in named and not var_kw:
                    close = difflib.get_close_matches(rest[0], list(named), n=1, cutoff=0.6)
                    hint = f" (did you mean {close[0]!r}?)" if close else ""
                    raise SweepError(pre + f"{path}: {rest[0]!r} is not a parameter of controller {c!r}{hint}; "
                                     "allowed: " + ", ".join(named))
            return
        ann = fields[part].annotation
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            model = ann
            if not rest:
                raise SweepError(pre + f"{path} is a section; vary one of its fields: " + ", ".join(ann.model_fields))
            continue
        if rest:
            raise SweepError(pre + f"{'.'.join(loc)} is a value, not a section (got {path!r})")
        return


def parse_vary(item: str, controllers: Sequence[str] = ("rac", "rac_dob")) -> Vary:
    """Parse and check ``KEY.PATH=SPEC`` (the key against the scenario schema, the spec's
    syntax and ranges). Values against the field's type are checked by :func:`plan_sweep`."""
    text = str(item)
    key, sep, spec_text = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise SweepError(f"--vary {text!r}: expected KEY.PATH=SPEC, e.g. plant.current[0]=uniform(0, 0.1) or "
                         "thrusters.tau=[0.02, 0.05]")
    m = re.fullmatch(r"(?P<key>[^\[\]]+?)\s*(?:\[\s*(?P<idx>[^\]]*)\s*\])?", key)
    if not m:
        raise SweepError(f"--vary {text!r}: bad key {key!r} (KEY.PATH or KEY.PATH[i])")
    base = m.group("key").strip()
    index = None
    if m.group("idx") is not None:
        if not re.fullmatch(r"\d+", m.group("idx").strip()):
            raise SweepError(f"--vary {text!r}: the component index must be a whole number >= 0 "
                             f"(got {m.group('idx')!r})")
        index = int(m.group("idx"))
    try:
        paths = _expand(base)
    except SweepError as exc:
        raise SweepError(f"--vary {text!r}: {exc}") from None
    if len(set(paths)) != len(paths):
        raise SweepError(f"--vary {text!r}: {{...}} names a field twice")
    for p in paths:
        _check_path(p, controllers, text)
    try:
        spec = parse_spec(spec_text)
    except SweepError as exc:
        raise SweepError(f"--vary {text!r}: {exc}") from None
    shown = base + ("" if index is None else f"[{index}]")
    axes, assigns = [], []
    if isinstance(spec, Vector):
        if index is not None:
            raise SweepError(f"--vary {text!r}: a per-component list [SPEC, ...] sets the whole field: write "
                             f"{base}=[...] or {base}[i]=SPEC")
        for i, it in enumerate(spec.items):
            if isinstance(it, (Grid, Random, Scale)):
                col = f"{base}[{i}]"
                is_scale = isinstance(it, Scale)
                inner = it.inner if is_scale else it
                col = f"scale({col})" if is_scale else col
                if isinstance(inner, Grid) and len(inner.values) and any(isinstance(v, list) for v in inner.values):
                    raise SweepError(f"--vary {text!r}: component {i} must take numbers, not lists")
                axes.append(Axis(col, inner, is_scale))
                assigns.append(Assignment(tuple(paths), i, col, scale=is_scale))
            else:
                assigns.append(Assignment(tuple(paths), i, None, value=it))
    else:
        is_scale = isinstance(spec, Scale)
        inner = spec.inner if is_scale else spec
        col = f"scale({shown})" if is_scale else shown
        axes.append(Axis(col, inner, is_scale))
        assigns.append(Assignment(tuple(paths), index, col, scale=is_scale))
    return Vary(text, base, index, spec, tuple(axes), tuple(assigns))


# ============================================================================ sampling


def _sample_seq(seed: int, i: int, j: int) -> np.random.SeedSequence:
    """SeedSequence(seed).spawn(...)[i].spawn(2)[j], built directly."""
    return np.random.SeedSequence(seed, spawn_key=(i, j))


def run_seed(seed: int, sample: int) -> int:
    """The simulation seed of a sample (sensor noise)."""
    return int(_sample_seq(seed, sample, 1).generate_state(1)[0])


def sample_count(varies: Sequence[Vary], n: int | None) -> tuple[int, int]:
    """(number of grid points, repeats per point)."""
    axes = [a for v in varies for a in v.axes]
    points = math.prod(len(a.spec.values) for a in axes if a.kind == "grid")
    randoms = [a.column for a in axes if a.kind == "random"]
    if randoms and n is None:
        raise SweepError("random specs (" + ", ".join(randoms) + ") need --n N, the number of samples "
                         "(at each grid point, if there are grids too)")
    if n is not None and n < 1:
        raise SweepError(f"--n must be >= 1 (got {n})")
    if points * (n or 1) > MAX_RUNS:
        raise SweepError(f"{points} grid points x {n or 1} samples = {points * (n or 1)} samples: at most "
                         f"{MAX_RUNS} in one sweep")
    return points, (n or 1)


def sample_parameters(varies: Sequence[Vary | str], n: int | None = None, seed: int = 0,
                      controllers: Sequence[str] = ("rac", "rac_dob")) -> list[dict[str, Any]]:
    """The drawn value of every axis column, per sample (see "Samples" in the module docstring)."""
    vs = [v if isinstance(v, Vary) else parse_vary(v, controllers) for v in varies]
    axes = [a for v in vs for a in v.axes]
    grid_axes = [a for a in axes if a.kind == "grid"]
    _, reps = sample_count(vs, n)
    points = list(itertools.product(*[range(len(a.spec.values)) for a in grid_axes]))
    out = []
    for g, point in enumerate(points):
        at = {a.column: a.spec.values[k] for a, k in zip(grid_axes, point)}
        for r in range(reps):
            i = g * reps + r
            rng = np.random.default_rng(_sample_seq(seed, i, 0))
            out.append({a.column: copy.deepcopy(at[a.column]) if a.kind == "grid" else a.spec.draw(rng) for a in axes})
    return out


# ============================================================================ plan

@dataclass
class Run:
    run_id: str
    sample: int
    controller: str
    seed: int
    key: str
    scenario: dict  # raw mapping (validates), outputs left to the runner
    draws: dict
    values: dict
    sets: list


@dataclass
class SweepPlan:
    scenario_path: str
    sets: tuple[str, ...]
    varies: list[Vary]
    n: int | None
    seed: int
    controllers: list[str]
    axes: list[Axis]
    samples: list[dict]
    runs: list[Run]
    definition: dict
    name: str


def _jsonable(v: Any) -> Any:
    from uvms_mj.scenario.schema import _jsonable as j

    return j(v)


def _override_value(params, key: str) -> Any:
    """An override key's value in a RobotParams (the inverse of params.apply_overrides)."""
    if key == "water_density":
        return float(params.rho)
    head, _, fld = key.partition(".")
    if head == "thrusters":
        thr = params.thrusters[0]
        return {"tau": float(thr.tau), "force_range": [float(v) for v in thr.force_range],
                "dead_zone": [float(v) for v in params.dead_zone]}[fld]
    b = params.body(head)
    if fld == "added_mass":
        return [float(b.added_mass[0]), float(b.added_mass[1]), float(b.added_inertia)]
    v = getattr(b, fld)
    return [float(x) for x in v] if isinstance(v, (tuple, list)) else float(v)


class _Bases:
    """The scenario's value of each field, per controller (for scale and KEY[i])."""

    def __init__(self, base_raw: dict) -> None:
        self.base_raw = base_raw
        self.cache: dict[str, tuple] = {}

    def scenario(self, controller: str):
        if controller not in self.cache:
            from uvms_mj.scenario.schema import apply_sets, resolved, validate_scenario

            raw = apply_sets(self.base_raw, [f"controller.name={controller}"])
            sc = validate_scenario(raw, f"the scenario with controller {controller!r}")
            self.cache[controller] = (sc, resolved(sc), {})
        return self.cache[controller]

    def value(self, controller: str, path: str) -> Any:
        from uvms_mj.plant.params import compile_robot, read_params
        from uvms_mj.plant.plant import models_dir
        from uvms_mj.scenario.schema import nominal_params, plant_overrides

        sc, res, memo = self.scenario(controller)
        parts = path.split(".")
        if parts[1:2] == ["overrides"] and parts[0] in ("plant", "nominal"):
            name = ".".join(parts[2:])
            given = res[parts[0]]["overrides"]
            if name in given:
                return copy.deepcopy(given[name])
            if parts[0] not in memo:
                if parts[0] == "nominal":
                    memo["nominal"] = nominal_params(sc)
                else:
                    memo["plant"] = read_params(compile_robot(models_dir() / "uvms.xml", plant_overrides(sc)))
            return _override_value(memo[parts[0]], name)
        node: Any = res
        for p in parts:
            node = node[p] if isinstance(node, dict) and p in node else None
        return copy.deepcopy(node)


def _times(factor: Any, base: Any) -> Any:
    if isinstance(base, list):
        return [float(factor) * float(b) for b in base]
    return float(factor) * float(base)


def _check_assignments(varies: Sequence[Vary], bases: _Bases, controllers: Sequence[str]) -> None:
    whole: dict[str, str] = {}
    comps: dict[tuple[str, int], str] = {}
    for v in varies:
        for a in v.assignments:
            for p in a.paths:
                if a.index is None:
                    if p in whole or any(k[0] == p for k in comps):
                        other = whole.get(p) or next(t for k, t in comps.items() if k[0] == p)
                        raise SweepError(f"--vary {v.text!r}: {p} is varied twice (also by {other!r})")
                    whole[p] = v.text
                else:
                    if p in whole or (p, a.index) in comps and comps[(p, a.index)] != v.text:
                        raise SweepError(f"--vary {v.text!r}: {p}[{a.index}] is varied twice (also by "
                                         f"{(whole.get(p) or comps[(p, a.index)])!r})")
                    comps[(p, a.index)] = v.text
                for c in controllers:
                    base = bases.value(c, p)
                    if a.index is not None:
                        n_comp = len(v.spec.items) if isinstance(v.spec, Vector) else None
                        if isinstance(v.spec, Vector) and isinstance(base, list) and len(base) != n_comp:
                            raise SweepError(f"--vary {v.text!r}: {p} has {len(base)} components, the spec gives "
                                             f"{n_comp}")
                        if not isinstance(v.spec, Vector):
                            if not isinstance(base, list):
                                raise SweepError(f"--vary {v.text!r}: {p} is not a vector (its value is "
                                                 f"{_fmt(base)}), so {p}[{a.index}] does not exist")
                            if a.index >= len(base):
                                raise SweepError(f"--vary {v.text!r}: index {a.index} out of range: {p} has "
                                                 f"{len(base)} components ({_fmt(base)})")
                    if a.scale:
                        b = base if a.index is None or not isinstance(base, list) else base[a.index]
                        ok = _is_num(b) or (isinstance(b, list) and b and all(_is_num(x) for x in b))
                        if not ok:
                            raise SweepError(f"--vary {v.text!r}: scale needs a numeric value to scale, but {p} is "
                                             f"{_fmt(b)} in the scenario (with controller {c})")
                    if a.index is None and a.column is not None and not a.scale and isinstance(base, list):
                        ax = next(x for x in v.axes if x.column == a.column)
                        vals = ax.spec.values if ax.kind == "grid" else (
                            ax.spec.args if ax.spec.dist == "choice" else (0.0,))
                        if any(not isinstance(x, list) for x in vals):
                            raise SweepError(
                                f"--vary {v.text!r}: {p} is a vector of {len(base)} ({_fmt(base)}): give each value "
                                f"as a list (e.g. {p}=[{_fmt(base)}, ...]), vary one component with {p}[0]=SPEC, "
                                f"or give a spec per component, e.g. "
                                f"{p}=[uniform(0, 0.1), {_fmt(base[1:] or [0])[1:-1]}]")


def _field_values(varies: Sequence[Vary], draws: dict, bases: _Bases, controller: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for v in varies:
        for a in v.assignments:
            val = draws[a.column] if a.column is not None else a.value
            for p in a.paths:
                base = bases.value(controller, p)
                if a.index is None:
                    out[p] = _times(val, base) if a.scale else copy.deepcopy(val)
                else:
                    if p not in out:
                        out[p] = copy.deepcopy(base) if isinstance(base, list) else [None] * len(v.spec.items)
                    comp_base = base[a.index] if isinstance(base, list) else None
                    out[p][a.index] = _times(val, comp_base) if a.scale else copy.deepcopy(val)
    return out


def _set_text(path: str, value: Any) -> str:
    return f"{path}={json.dumps(_jsonable(value))}"


def _run_key(resolved_dict: dict) -> str:
    d = {k: v for k, v in resolved_dict.items() if k != "outputs"}
    return hashlib.sha256(json.dumps(d, sort_keys=True, separators=(",", ":")).encode()).hexdigest()[:16]


def check_controllers(controllers: Sequence[str]) -> list[str]:
    from uvms_mj.control import available

    names = [c.strip() for c in controllers if c and c.strip()]
    if not names:
        raise SweepError(f"--controllers: none given; registered: {', '.join(available())}")
    unknown = [c for c in names if c not in available()]
    if unknown:
        hints = []
        for c in unknown:
            close = difflib.get_close_matches(c, available(), n=1, cutoff=0.6)
            hints.append(c + (f" (did you mean {close[0]!r}?)" if close else ""))
        raise SweepError(f"--controllers: unknown controller(s) {', '.join(hints)}; "
                         f"registered: {', '.join(available())}")
    if len(set(names)) != len(names):
        raise SweepError(f"--controllers: a controller is listed twice ({', '.join(names)})")
    return names


def check_engine(engine: str) -> None:
    """Unknown engine, or Ray asked for and missing: SweepError (before any run)."""
    if engine not in ENGINES:
        raise SweepError(f"--engine {engine!r}: unknown; choose one of {', '.join(ENGINES)}")
    if engine == "ray":
        try:
            import ray  # noqa: F401
        except ImportError:
            raise SweepError(RAY_MISSING) from None


def plan_sweep(
    scenario: str | Path,
    vary: Sequence[str],
    n: int | None = None,
    seed: int = 0,
    controllers: Sequence[str] | str | None = ("rac", "rac_dob"),
    sets: Sequence[str] = (),
) -> SweepPlan:
    """Parse, sample and validate a sweep: every run's scenario is validated here, so a bad
    spec, key, range, sampled value or controller raises SweepError before anything runs."""
    from uvms_mj.scenario.schema import (
        ScenarioError,
        apply_sets,
        build,
        load_scenario,
        resolved,
        validate_scenario,
    )

    if isinstance(controllers, str):
        controllers = controllers.split(",")
    try:
        base = load_scenario(scenario, tuple(sets))
    except ScenarioError as exc:
        raise SweepError(str(exc)) from None
    names = check_controllers(controllers if controllers else [base.controller.name])
    if not vary:
        raise SweepError("give at least one --vary KEY.PATH=SPEC")
    if seed is None or int(seed) < 0:
        raise SweepError(f"--seed must be >= 0 (got {seed})")
    varies = [parse_vary(v, names) for v in vary]
    cols = [a.column for v in varies for a in v.axes]
    dup = sorted({c for c in cols if cols.count(c) > 1})
    if dup:
        raise SweepError(f"--vary: {', '.join(dup)} varied twice")
    base_raw = base.model_dump(mode="json")
    base_raw.pop("outputs", None)
    base_raw["outputs"] = {"log": None, "video": False, "plots": False}
    bases = _Bases(base_raw)
    try:
        for c in names:
            bases.scenario(c)
    except ScenarioError as exc:
        raise SweepError(str(exc)) from None
    _check_assignments(varies, bases, names)
    samples = sample_parameters(varies, n, seed)
    width = max(4, len(str(len(samples) - 1)))
    runs, errors = [], []
    for i, draws in enumerate(samples):
        s = run_seed(seed, i)
        for c in names:
            values = _field_values(varies, draws, bases, c)
            run_sets = [f"controller.name={c}", f"seed={s}"] + [_set_text(p, v) for p, v in values.items()]
            rid = f"s{i:0{width}d}-{c}"
            try:
                raw = apply_sets(base_raw, run_sets)
                sc = validate_scenario(raw, f"run {rid} ({', '.join(f'{k}={_fmt(x)}' for k, x in draws.items())})")
            except ScenarioError as exc:
                errors.append(str(exc))
                continue
            runs.append(Run(rid, i, c, s, _run_key(resolved(sc)), raw, draws, values, list(sets) + run_sets))
    if errors:
        more = f"\n... and {len(errors) - 5} more runs with invalid values" if len(errors) > 5 else ""
        raise SweepError("sampled values the scenario does not allow (narrow the spec):\n"
                         + "\n".join(errors[:5]) + more)
    # A build catches combinations that fail only when built, and compiles the native backend
    # into its cache before workers start (one compile, not one per worker).
    for c in names:
        first = next(r for r in runs if r.controller == c)
        try:
            build(validate_scenario(first.scenario))
        except (ScenarioError, ValueError) as exc:
            raise SweepError(f"run {first.run_id}: {exc}") from None
    definition = {
        "format": FORMAT,
        "scenario": _jsonable({k: v for k, v in base_raw.items() if k != "outputs"}),
        "vary": [str(v) for v in varies],
        "n": sample_count(varies, n)[1],
        "seed": int(seed),
        "controllers": names,
    }
    return SweepPlan(str(scenario), tuple(sets), varies, n, int(seed), names,
                     [a for v in varies for a in v.axes], samples, runs, definition, base.name)


# ============================================================================ execution


def _one_line(text: str, limit: int = 400) -> str:
    s = " ".join(str(text).split())
    return s if len(s) <= limit else s[:limit - 3] + "..."


#: The sweep's process, in a worker of the process engine (None elsewhere).
_PARENT_PID: int | None = None


def _parent_gone() -> bool:
    return _PARENT_PID is not None and os.getppid() != _PARENT_PID


def _watch_parent() -> None:
    while True:
        time.sleep(0.5)
        if _parent_gone():
            os._exit(1)


def _worker_init(parent: int) -> None:
    """Initializer of the process engine's workers: a worker ends with its sweep, even after
    ``kill -9`` of the sweep (Linux: PR_SET_PDEATHSIG; everywhere: a thread polling
    os.getppid() every 0.5 s, and a check before each run)."""
    global _PARENT_PID
    import signal
    import sys
    import threading

    _PARENT_PID = parent
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    if _parent_gone():
        os._exit(1)
    threading.Thread(target=_watch_parent, name="uvms-mj-parent-watch", daemon=True).start()


def execute_run(task: dict) -> dict:
    """Run one task (in a worker): never raises for a failing run; returns status, reason,
    metrics, t_end, wall_s."""
    if _parent_gone():
        os._exit(1)
    t0 = time.perf_counter()
    out: dict[str, Any] = {"status": "error", "reason": "", "metrics": {}, "t_end": float("nan")}
    try:
        from uvms_mj.sim.experiment import metrics
        from uvms_mj.scenario.schema import validate_scenario

        sc = validate_scenario(task["scenario"], f"run {task['run_id']}")
        log = task.get("log")
        if log:
            from uvms_mj.io.writer import McapRecorder
            from uvms_mj.scenario.schema import build, resolved

            plant, _ = build(sc)
            Path(log).parent.mkdir(parents=True, exist_ok=True)
            meta = {"scenario": resolved(sc), "seed": sc.seed, "sweep": {"run_id": task["run_id"],
                                                                         "sample": task["sample"]}}
            with McapRecorder(log, plant.params, meta) as rec:
                res = run_scenario(sc, sink=rec.write_sample)
                rec.close(status=res.status, reason=res.reason, meta=res.meta)
        else:
            res = run_scenario(sc)
        out["status"], out["reason"] = str(res.status), _one_line(res.reason)
        out["t_end"] = float(res.t[-1]) if len(res.t) else 0.0
        try:
            out["metrics"] = {k: float(v) for k, v in metrics(res).items()}
        except Exception as exc:  # noqa: BLE001 - e.g. no sample at all
            out["reason"] = _one_line(f"{out['reason']}; metrics unavailable: {type(exc).__name__}: {exc}")
    except Exception as exc:  # noqa: BLE001 - recorded, never stops the sweep
        out["status"], out["reason"] = "error", _one_line(f"{type(exc).__name__}: {exc}")
    out["wall_s"] = time.perf_counter() - t0
    return out


def run_scenario(scenario, sink=None):
    """uvms_mj.scenario.schema.run_scenario (a module attribute, so that tests can replace it)."""
    from uvms_mj.scenario.schema import run_scenario as rs

    return rs(scenario, sink=sink)


def _crashed(exc: BaseException) -> dict:
    return {"status": "crashed", "reason": _one_line(f"worker died: {type(exc).__name__}: {exc}"), "metrics": {},
            "t_end": float("nan"), "wall_s": float("nan")}


def _engine_serial(tasks: list[dict], workers: int, done: Callable[[dict, dict], None]) -> None:
    for t in tasks:
        done(t, execute_run(t))


def _engine_process(tasks: list[dict], workers: int, done: Callable[[dict, dict], None]) -> None:
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    ctx = mp.get_context("spawn")
    queue = list(tasks)
    attempts: dict[str, int] = {}
    while queue:
        pool = ProcessPoolExecutor(max_workers=max(1, min(workers, len(queue))), mp_context=ctx,
                                   initializer=_worker_init, initargs=(os.getpid(),))
        try:
            futs = {pool.submit(execute_run, t): t for t in queue}
            queue = []
            for fut in as_completed(futs):
                t = futs[fut]
                try:
                    res = fut.result()
                except BrokenProcessPool as exc:
                    attempts[t["run_id"]] = attempts.get(t["run_id"], 0) + 1
                    if attempts[t["run_id"]] >= MAX_ATTEMPTS:
                        done(t, _crashed(exc))
                    else:
                        queue.append(t)
                    continue
                except Exception as exc:  # noqa: BLE001 - e.g. a result that does not unpickle
                    res = {"status": "error", "reason": _one_line(f"{type(exc).__name__}: {exc}"), "metrics": {},
                           "t_end": float("nan"), "wall_s": float("nan")}
                done(t, res)
        except BaseException:
            pool.shutdown(wait=True, cancel_futures=True)
            raise
        pool.shutdown(wait=True)


def _engine_ray(tasks: list[dict], workers: int, done: Callable[[dict, dict], None]) -> None:
    try:
        import ray
    except ImportError:
        raise SweepError(RAY_MISSING) from None
    started = False
    if not ray.is_initialized():
        if os.environ.get("RAY_ADDRESS"):
            ray.init(log_to_driver=False)
        else:
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
        started = True
    try:
        remote = ray.remote(num_cpus=1, max_retries=MAX_ATTEMPTS - 1)(execute_run)
        pending = {remote.remote(t): t for t in tasks}
        try:
            while pending:
                ready, _ = ray.wait(list(pending), num_returns=1)
                for ref in ready:
                    t = pending.pop(ref)
                    try:
                        res = ray.get(ref)
                    except Exception as exc:  # noqa: BLE001 - worker crash, task error
                        res = _crashed(exc)
                    done(t, res)
        except BaseException:
            for ref in pending:
                ray.cancel(ref, force=True)
            raise
    finally:
        if started:
            ray.shutdown()


_ENGINES = {"process": _engine_process, "ray": _engine_ray, "serial": _engine_serial}


# ============================================================================ results


def _columns(plan: SweepPlan, rows: Iterable[dict]) -> list[str]:
    extra = sorted({k for r in rows for k in r.get("metrics_extra", ())})
    return (["run_id", "sample", "controller", "seed"] + [a.column for a in plan.axes] + list(METRICS) + extra
            + ["status", "reason", "t_end", "wall_s", "log", "values", "sets", "key"])


def _row(run: Run, res: dict, log: str | None) -> dict:
    row: dict[str, Any] = {"run_id": run.run_id, "sample": run.sample, "controller": run.controller, "seed": run.seed}
    row.update(run.draws)
    m = res.get("metrics") or {}
    for k in METRICS:
        row[k] = m.get(k, float("nan"))
    extra = [k for k in m if k not in METRICS]
    for k in extra:
        row[k] = m[k]
    row["metrics_extra"] = extra
    row.update(status=res["status"], reason=res.get("reason", ""), t_end=res.get("t_end", float("nan")),
               wall_s=res.get("wall_s", float("nan")), log=log or "", values=run.values, sets=run.sets, key=run.key)
    return row


def _cell(v: Any) -> Any:
    if isinstance(v, (dict, list, tuple)):
        return json.dumps(_jsonable(v))
    if isinstance(v, float):
        return repr(v)
    if v is None:
        return ""
    return v


def _write_table(plan: SweepPlan, rows: list[dict], out: Path) -> list[Path]:
    cols = _columns(plan, rows)
    paths = []
    tmp = out / "results.csv.tmp"
    with open(tmp, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for r in rows:
            w.writerow([_cell(r.get(c, "")) for c in cols])
    os.replace(tmp, out / "results.csv")
    paths.append(out / "results.csv")
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return paths
    data = {c: [(json.dumps(_jsonable(r.get(c))) if isinstance(r.get(c), (dict, list)) else r.get(c)) for r in rows]
            for c in cols}
    for c in [a.column for a in plan.axes]:
        if any(not _is_num(v) for v in data[c]):
            data[c] = [json.dumps(_jsonable(v)) for v in data[c]]
    pq.write_table(pa.table(data), out / "results.parquet")
    paths.append(out / "results.parquet")
    return paths


def read_results(path: str | Path) -> list[dict]:
    """results.csv back as dicts (numbers parsed, JSON columns decoded)."""
    p = Path(path)
    if p.is_dir():
        p = p / "results.csv"
    rows = []
    with open(p, newline="", encoding="utf-8") as f:
        for r in csv.DictReader(f):
            out = {}
            for k, v in r.items():
                if k in ("values", "sets"):
                    out[k] = json.loads(v) if v else None
                elif k in ("run_id", "controller", "status", "reason", "log", "key"):
                    out[k] = v
                else:
                    try:
                        out[k] = int(v) if re.fullmatch(r"-?\d+", v) else float(v)
                    except ValueError:
                        try:
                            out[k] = json.loads(v)
                        except ValueError:
                            out[k] = v
            rows.append(out)
    return rows


def _read_jsonl(path: Path) -> list[dict]:
    rows = []
    if not path.exists():
        return rows
    with open(path, encoding="utf-8") as f:
        for line in f:
            line = line.strip()
            if not line:
                continue
            try:
                rows.append(json.loads(line))
            except ValueError:
                continue  # a line cut by a kill
    return rows


def _diff(old: dict, new: dict) -> list[str]:
    out = []
    for k in sorted(set(old) | set(new)):
        if old.get(k) != new.get(k):
            if k == "scenario":
                sub = sorted(s for s in set(old.get(k) or {}) | set(new.get(k) or {})
                             if (old.get(k) or {}).get(s) != (new.get(k) or {}).get(s))
                out.append(f"scenario ({', '.join(sub)})")
            else:
                out.append(f"{k}: {json.dumps(old.get(k))} -> {json.dumps(new.get(k))}")
    return out


_OUR_FILES = ("sweep.json", "runs.jsonl", "results.csv", "results.parquet", "summary.json", "sweep_metrics.png",
              "sweep_ratio.png")


@dataclass
class SweepOutcome:
    out_dir: Path
    rows: list[dict]
    planned: int
    skipped: int
    ran: int
    elapsed_s: float
    summary: dict
    figures: list[Path] = field(default_factory=list)
    tables: list[Path] = field(default_factory=list)
    interrupted: bool = False

    @property
    def runs_per_s(self) -> float:
        return self.ran / self.elapsed_s if self.ran and self.elapsed_s > 0 else float("nan")


def prepare_out(plan: SweepPlan, out_dir: str | Path, fresh: bool = False) -> dict[str, dict]:
    """Check or create DIR's sweep definition; return the finished runs by key."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise SweepError(f"--out-dir {out}: exists and is not a folder")
    spec = out / "sweep.json"
    if fresh and out.exists():
        for name in _OUR_FILES:
            (out / name).unlink(missing_ok=True)
        if (out / "logs").is_dir():
            shutil.rmtree(out / "logs")
    if spec.exists():
        try:
            old = json.loads(spec.read_text(encoding="utf-8"))
        except ValueError:
            raise SweepError(f"--out-dir {out}: {spec} is not readable JSON; use another --out-dir or --fresh") from None
        old_def = old.get("definition", {})
        new_def = json.loads(json.dumps(plan.definition))
        if old_def != new_def:
            raise SweepError(f"--out-dir {out} holds a different sweep; differs: " + "; ".join(_diff(old_def, new_def))
                             + ". Rerun with the same arguments to resume, choose another --out-dir, or add --fresh to "
                             "delete the old results.")
    elif out.exists() and (out / "runs.jsonl").exists():
        raise SweepError(f"--out-dir {out}: runs.jsonl without sweep.json; use another --out-dir or --fresh")
    out.mkdir(parents=True, exist_ok=True)
    if not spec.exists():
        from uvms_mj import __version__

        spec.write_text(json.dumps({"definition": plan.definition, "source": plan.scenario_path,
                                    "sets": list(plan.sets), "uvms_mj": __version__,
                                    "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}, indent=1),
                        encoding="utf-8")
    wanted = {r.key for r in plan.runs}
    finished = {}
    for row in _read_jsonl(out / "runs.jsonl"):
        if row.get("key") in wanted and row.get("status") in FINISHED:
            finished[row["key"]] = row
    return finished


def run_sweep(
    plan: SweepPlan,
    out_dir: str | Path,
    workers: int | None = None,
    engine: str = "process",
    logs: bool = False,
    fresh: bool = False,
    on_run: Callable[[dict, int, int], None] | None = None,
    figures: bool = True,
) -> SweepOutcome:
    """Run the plan's unfinished runs and write the table, summary and figures into out_dir.

    ``on_run(row, k, total)`` is called as each run finishes. KeyboardInterrupt (Ctrl-C, or
    SIGTERM inside recorder.handle_sigterm) stops the sweep; finished runs are kept (table
    written) and the exception propagates.
    """
    from uvms_mj.io.interrupts import _critical

    check_engine(engine)
    workers = int(workers or _cpu_count())
    if workers < 1:
        raise SweepError(f"--workers must be >= 1 (got {workers})")
    out = Path(out_dir)
    finished = prepare_out(plan, out, fresh)
    todo = [r for r in plan.runs if r.key not in finished]
    by_id = {r.run_id: r for r in todo}
    tasks = [{"run_id": r.run_id, "sample": r.sample, "scenario": r.scenario,
              "log": str(out / "logs" / f"{r.run_id}.mcap") if logs else None} for r in todo]
    rows_by_key = dict(finished)
    k = 0
    record = out / "runs.jsonl"
    if record.exists() and record.stat().st_size and not record.read_bytes().endswith(b"\n"):
        with open(record, "a", encoding="utf-8") as f:
            f.write("\n")  # end a line cut by a kill (it is skipped when read)
    jsonl = open(record, "a", encoding="utf-8")  # noqa: SIM115 - closed in the finally below

    def done(task: dict, res: dict) -> None:
        nonlocal k
        run = by_id[task["run_id"]]
        log = task["log"] if task["log"] and Path(task["log"]).exists() else None
        row = _row(run, res, log)
        rows_by_key[run.key] = row
        with _critical():  # SIGTERM / Ctrl-C (inside recorder.handle_sigterm) wait for the whole line
            jsonl.write(json.dumps(_jsonable(row), allow_nan=True) + "\n")
            jsonl.flush()
        k += 1
        if on_run is not None:
            on_run(row, k, len(tasks))

    t0 = time.perf_counter()
    interrupted = True  # until the engine returns
    try:
        if tasks:
            _ENGINES[engine](tasks, workers, done)
        interrupted = False
    finally:
        jsonl.close()
        elapsed = time.perf_counter() - t0
        order = {r.key: i for i, r in enumerate(plan.runs)}
        rows = sorted((r for key, r in rows_by_key.items() if key in order), key=lambda r: order[r["key"]])
        tables = _write_table(plan, rows, out)
        summary = summarize(rows, plan.controllers, [a.column for a in plan.axes])
        summary.update(planned=len(plan.runs), skipped=len(finished), ran=k, elapsed_s=elapsed,
                       runs_per_s=(k / elapsed if k and elapsed > 0 else None), workers=workers, engine=engine)
        (out / "summary.json").write_text(json.dumps(_jsonable(summary), indent=1, allow_nan=True), encoding="utf-8")
        figs = []
        if figures and not interrupted and rows:
            discrete = [a.column for a in plan.axes if a.kind == "grid" or a.spec.dist == "choice"]
            figs = plot_sweep(rows, [a.column for a in plan.axes], plan.controllers, out, title=plan.name,
                              discrete=discrete)
    return SweepOutcome(out, rows, len(plan.runs), len(finished), k, elapsed, summary, figs, tables, interrupted)


def _cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


# ============================================================================ summary


def _stats(x: Sequence[float]) -> dict:
    a = np.asarray([v for v in x if v is not None and math.isfinite(v)], dtype=float)
    if not a.size:
        return {"n": 0, "median": None, "p10": None, "p90": None}
    return {"n": int(a.size), "median": float(np.median(a)), "p10": float(np.percentile(a, 10)),
            "p90": float(np.percentile(a, 90)), "min": float(a.min()), "max": float(a.max())}


def _pairs(rows: Sequence[dict], ref: str, other: str) -> list[tuple[dict, dict]]:
    by = {(r["sample"], r["controller"]): r for r in rows}
    out = []
    for (s, c), r in sorted(by.items(), key=lambda kv: kv[0][0]):
        if c == ref and (s, other) in by:
            o = by[(s, other)]
            if r["status"] == "ok" and o["status"] == "ok":
                out.append((r, o))
    return out


def summarize(rows: Sequence[dict], controllers: Sequence[str], columns: Sequence[str] = ()) -> dict:
    """Counts, per-controller metric distributions (ok runs) and paired ratios (each
    controller / the first, samples where both are ok)."""
    out: dict[str, Any] = {"runs": len(rows), "controllers": {}, "ratios": {}, "failures": []}
    for c in controllers:
        rs = [r for r in rows if r["controller"] == c]
        ok = [r for r in rs if r["status"] == "ok"]
        statuses: dict[str, int] = {}
        for r in rs:
            statuses[r["status"]] = statuses.get(r["status"], 0) + 1
        out["controllers"][c] = {"runs": len(rs), "ok": len(ok), "failed": len(rs) - len(ok), "statuses": statuses,
                                 "metrics": {m: _stats([r[m] for r in ok]) for m in SUMMARY_METRICS}}
    for c in controllers[1:]:
        pairs = _pairs(rows, controllers[0], c)
        rat = {}
        for m in SUMMARY_METRICS:
            vals = [o[m] / r[m] for r, o in pairs if r[m] and math.isfinite(r[m]) and math.isfinite(o[m])]
            st = _stats(vals)
            st["below_1"] = float(np.mean(np.asarray(vals) < 1.0)) if vals else None
            rat[m] = st
        out["ratios"][f"{c}/{controllers[0]}"] = {"pairs": len(pairs), "metrics": rat}
    out["failures"] = [{"run_id": r["run_id"], "status": r["status"], "reason": r["reason"],
                        **{k: r.get(k) for k in columns}} for r in rows if r["status"] != "ok"]
    return out


def _g(v: Any) -> str:
    return "-" if v is None else f"{v:.3g}"


def format_summary(summary: dict) -> str:
    """The summary as text: counts, metric distributions per controller, paired ratios, failures."""
    ctrl = summary["controllers"]
    lines = [f"{'controller':<12}{'runs':>6}{'ok':>6}{'failed':>8}"]
    for c, s in ctrl.items():
        extra = ", ".join(f"{k} {v}" for k, v in s["statuses"].items() if k != "ok")
        lines.append(f"{c:<12}{s['runs']:>6}{s['ok']:>6}{s['failed']:>8}" + (f"  ({extra})" if extra else ""))
    def cell(st: dict) -> str:
        return f"{_g(st['median'])} [{_g(st['p10'])}, {_g(st['p90'])}]"

    w = max([len(cell(st)) for s in ctrl.values() for st in s["metrics"].values()] + [len(c) for c in ctrl]) + 3
    lines.append(f"{'ok runs: median [10 %, 90 %]':<28}" + "".join(f"{c:>{w}}" for c in ctrl))
    for m, label in SUMMARY_METRICS.items():
        lines.append(f"{label:<28}" + "".join(f"{cell(s['metrics'][m]):>{w}}" for s in ctrl.values()))
    for name, r in summary["ratios"].items():
        lines.append(f"paired ratio {name} ({r['pairs']} pairs, both ok): median [10 %, 90 %], share < 1")
        for m, st in r["metrics"].items():
            b = st.get("below_1")
            share = "-" if b is None else f"{100 * b:.0f} %"
            lines.append(f"  {SUMMARY_METRICS[m].split(' [')[0]:<26}{cell(st):>{w}}   {share}")
    fails = summary.get("failures") or []
    if fails:
        lines.append(f"failed runs: {len(fails)}")
        for f in fails[:10]:
            lines.append(f"  {f['run_id']}: {f['status']}: {f['reason']}")
        if len(fails) > 10:
            lines.append(f"  ... and {len(fails) - 10} more (results.csv)")
    return "\n".join(lines)


# ============================================================================ figures

_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b")
_DPI = 110


def _xdata(rows: Sequence[dict], col: str) -> tuple[np.ndarray, list[str] | None]:
    """Numeric x of a column, or category positions and labels."""
    vals = [r.get(col) for r in rows]
    if all(_is_num(v) for v in vals):
        return np.asarray(vals, dtype=float), None
    labels = []
    for v in vals:
        s = v if isinstance(v, str) else json.dumps(_jsonable(v))
        if s not in labels:
            labels.append(s)
    pos = [labels.index(v if isinstance(v, str) else json.dumps(_jsonable(v))) for v in vals]
    return np.asarray(pos, dtype=float), labels


def _binned_median(ax, x: np.ndarray, y: np.ndarray, color: str) -> None:
    if len(x) < 6:
        return
    ux = np.unique(x)
    if len(ux) <= 12:
        centers = ux
        meds = [np.median(y[x == u]) for u in ux]
    else:
        edges = np.quantile(x, np.linspace(0, 1, 7))
        centers, meds = [], []
        for lo, hi in itertools.pairwise(edges):
            sel = (x >= lo) & (x <= hi)
            if sel.sum() >= 2:
                centers.append(float(np.median(x[sel])))
                meds.append(float(np.median(y[sel])))
    ax.plot(centers, meds, "-", color=color, lw=1.6, alpha=0.9)


def _logy(ax, ys: Sequence[np.ndarray]) -> None:
    a = np.concatenate([y[np.isfinite(y)] for y in ys if len(y)]) if ys else np.array([])
    if a.size and np.all(a > 0) and a.max() / a.min() > 30:
        ax.set_yscale("log")


def _fail_marks(ax, x: np.ndarray, color: str, label: str | None, k: int = 0) -> None:
    """Failed runs as crosses along the top of the panel (one row per controller)."""
    if not len(x):
        return
    import matplotlib.transforms as mtransforms

    trans = mtransforms.blended_transform_factory(ax.transData, ax.transAxes)
    ax.plot(x, np.full(len(x), 0.96 - 0.06 * k), "x", color=color, ms=7, mew=1.6, transform=trans, clip_on=False,
            label=label)


def _cat_ticks(ax, labels: list[str] | None) -> None:
    if labels is not None:
        ax.set_xticks(range(len(labels)))
        ax.set_xticklabels([lab if len(lab) <= 14 else lab[:13] + "…" for lab in labels], rotation=20, fontsize=7)


def _jitter(x: np.ndarray, labels, i: int, n: int, discrete: bool, span: float) -> np.ndarray:
    """Side by side per controller on discrete axes (grids, choices); continuous x as is."""
    if labels is not None:
        return x + (i - (n - 1) / 2) * 0.12
    if discrete:
        return x + (i - (n - 1) / 2) * 0.12 * span
    return x


def _spacing(rows: Sequence[dict], col: str) -> float:
    x, labels = _xdata(rows, col)
    if labels is not None:
        return 1.0
    u = np.unique(x[np.isfinite(x)])
    return float(np.min(np.diff(u))) if len(u) > 1 else 1.0


def plot_sweep(rows: Sequence[dict], columns: Sequence[str], controllers: Sequence[str], out_dir: str | Path,
               title: str = "sweep", discrete: Iterable[str] | None = None) -> list[Path]:
    """``sweep_metrics.png`` and (with two or more controllers) ``sweep_ratio.png``.

    ``discrete``: the columns drawn from a set of values (grids, choices), whose points are set
    side by side per controller (default: columns with at most 12 distinct values)."""
    from matplotlib.figure import Figure

    out = Path(out_dir)
    cols = list(columns)
    if discrete is None:
        discrete = [c for c in cols if len({json.dumps(_jsonable(r.get(c))) for r in rows}) <= 12]
    disc = {c: (c in set(discrete)) for c in cols}
    span = {c: _spacing(rows, c) for c in cols}
    mets = list(SUMMARY_METRICS)
    ncol = len(cols) + 1
    paths = []
    fig = Figure(figsize=(3.4 * ncol + 0.6, 2.5 * len(mets) + 0.9), dpi=_DPI, layout="constrained")
    axs = fig.subplots(len(mets), ncol, squeeze=False, sharey="row")
    n_ok = {c: sum(1 for r in rows if r["controller"] == c and r["status"] == "ok") for c in controllers}
    n_all = {c: sum(1 for r in rows if r["controller"] == c) for c in controllers}
    for i, m in enumerate(mets):
        for j, col in enumerate(cols):
            ax = axs[i, j]
            ys = []
            for k, c in enumerate(controllers):
                rc = [r for r in rows if r["controller"] == c]
                ok = [r for r in rc if r["status"] == "ok"]
                bad = [r for r in rc if r["status"] != "ok"]
                color = _COLORS[k % len(_COLORS)]
                if ok:
                    x, labels = _xdata(ok, col)
                    y = np.asarray([r[m] for r in ok], dtype=float)
                    ax.scatter(_jitter(x, labels, k, len(controllers), disc[col], span[col]), y, s=12, color=color,
                               alpha=0.6, lw=0, label=c if (i == 0 and j == 0) else None)
                    _binned_median(ax, x, y, color)
                    _cat_ticks(ax, labels)
                    ys.append(y)
                if bad:
                    xb, lb = _xdata(bad, col)
                    _fail_marks(ax, _jitter(xb, lb, k, len(controllers), disc[col], span[col]), color,
                                f"{c} failed" if (i == 0 and j == 0) else None, k)
                    _cat_ticks(ax, lb)
            if j == 0:
                _logy(ax, ys)
            ax.grid(True, alpha=0.3)
            if i == len(mets) - 1:
                ax.set_xlabel(col, fontsize=8)
            if j == 0:
                ax.set_ylabel(SUMMARY_METRICS[m], fontsize=8)
            ax.tick_params(labelsize=7)
        ax = axs[i, -1]
        data = [np.asarray([r[m] for r in rows if r["controller"] == c and r["status"] == "ok"], dtype=float)
                for c in controllers]
        present = [(c, d) for c, d in zip(controllers, data) if d.size]
        if present:
            bp = ax.boxplot([d for _, d in present], whis=(10, 90), showfliers=True, patch_artist=True,
                            flierprops={"markersize": 3})
            ax.set_xticks(range(1, len(present) + 1))
            ax.set_xticklabels([c for c, _ in present], fontsize=8)
            for patch, (c, _) in zip(bp["boxes"], present):
                patch.set_facecolor(_COLORS[list(controllers).index(c) % len(_COLORS)])
                patch.set_alpha(0.4)
        ax.grid(True, alpha=0.3)
        ax.tick_params(labelsize=7)
        if i == 0:
            ax.set_title("all samples (box: 25-75 %, whiskers 10-90 %)", fontsize=8)
    counts = ", ".join(f"{c}: {n_ok[c]}/{n_all[c]} ok" for c in controllers)
    fig.suptitle(f"{title}: metrics against the varied parameters ({counts}; lines: medians; x: failed runs)",
                 fontsize=10)
    fig.legend(loc="outside lower center", ncol=2 * len(controllers), fontsize=8)
    p = out / "sweep_metrics.png"
    fig.savefig(p)
    paths.append(p)

    if len(controllers) >= 2:
        ref = controllers[0]
        fig = Figure(figsize=(3.4 * ncol + 0.6, 2.5 * len(mets) + 0.9), dpi=_DPI, layout="constrained")
        axs = fig.subplots(len(mets), ncol, squeeze=False, sharey="row")
        notes = []
        for k, c in enumerate(controllers[1:], start=1):
            pairs = _pairs(rows, ref, c)
            notes.append(f"{c}/{ref}: {len(pairs)} pairs")
        for i, m in enumerate(mets):
            hist_data = []
            for k, c in enumerate(controllers[1:], start=1):
                color = _COLORS[k % len(_COLORS)]
                pairs = [(r, o) for r, o in _pairs(rows, ref, c)
                         if math.isfinite(r[m]) and r[m] > 0 and math.isfinite(o[m])]
                if not pairs:
                    continue
                ratio = np.asarray([o[m] / r[m] for r, o in pairs], dtype=float)
                hist_data.append((c, color, ratio))
                for j, col in enumerate(cols):
                    ax = axs[i, j]
                    x, labels = _xdata([r for r, _ in pairs], col)
                    ax.scatter(_jitter(x, labels, k - 1, len(controllers) - 1, disc[col], span[col]), ratio, s=12,
                               color=color, alpha=0.6, lw=0, label=f"{c}/{ref}" if (i == 0 and j == 0) else None)
                    _binned_median(ax, x, ratio, color)
                    _cat_ticks(ax, labels)
            for j, col in enumerate(cols):
                ax = axs[i, j]
                ax.axhline(1.0, color="k", lw=0.8, ls="--")
                if j == 0:
                    _logy(ax, [h[2] for h in hist_data] + [np.ones(1)])
                ax.grid(True, alpha=0.3)
                ax.tick_params(labelsize=7)
                if i == len(mets) - 1:
                    ax.set_xlabel(col, fontsize=8)
                if j == 0:
                    ax.set_ylabel(f"ratio of {SUMMARY_METRICS[m].split(' [')[0]}", fontsize=8)
            ax = axs[i, -1]
            if hist_data:
                bp = ax.boxplot([h[2] for h in hist_data], whis=(10, 90), showfliers=True, patch_artist=True,
                                flierprops={"markersize": 3}, widths=0.5)
                for patch, (c, color, _) in zip(bp["boxes"], hist_data):
                    patch.set_facecolor(color)
                    patch.set_alpha(0.4)
                ax.set_xticks(range(1, len(hist_data) + 1))
                ax.set_xticklabels([f"{c}/{ref}" for c, _, _ in hist_data], fontsize=8)
                for h, (c, color, ratio) in enumerate(hist_data):
                    med, p10, p90 = np.median(ratio), np.percentile(ratio, 10), np.percentile(ratio, 90)
                    ax.text(0.97, 0.95 - 0.16 * h, f"{c}/{ref}: median {med:.3g}\n10-90 % [{p10:.3g}, {p90:.3g}]",
                            transform=ax.transAxes, ha="right", va="top", fontsize=7, color=color)
            ax.axhline(1.0, color="k", lw=0.8, ls="--")
            ax.grid(True, alpha=0.3)
            ax.tick_params(labelsize=7)
            if i == 0:
                ax.set_title("all pairs (box: 25-75 %, whiskers 10-90 %)", fontsize=8)
        fig.suptitle(f"{title}: paired ratio to {ref} (same parameters and seed; < 1: better than {ref}; "
                     f"{'; '.join(notes)})", fontsize=10)
        if any(ax.get_legend_handles_labels()[0] for ax in axs.flat):
            fig.legend(loc="outside lower center", ncol=len(controllers), fontsize=8)
        p = out / "sweep_ratio.png"
        fig.savefig(p)
        paths.append(p)
    return paths
