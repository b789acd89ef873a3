"""A sweep's plan: the ``--vary`` keys checked against the scenario schema, the samples drawn
(reproducibly, from the sweep seed) and every run's scenario validated before anything runs."""

from __future__ import annotations

import copy
import difflib
import hashlib
import itertools
import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel

from uvms_mj.analysis.sweep.spec import Grid, Random, Scale, Spec, SweepError, Vector, _fmt, _is_num, parse_spec

#: Version of the sweep definition written to ``sweep.json``.
FORMAT = 1
#: Largest number of runs in one sweep (checked before anything runs).
MAX_RUNS = 100_000


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


def _check_path(path: str, controllers: Sequence[str], item: str, robot: str = "paper") -> None:
    """The dotted path names a scenario field (schema walk; overrides and controller params
    checked by name: the paper robot's parameter names, or on a model-file robot
    ``<element or role>.<field>``, checked on its model when each run is validated). Raises
    SweepError naming it."""
    from uvms_mj.control import available
    from uvms_mj.plant.params import HYDRO_BODIES, OVERRIDE_KEYS
    from uvms_mj.scenario.paper import OVERRIDE_NAMES
    from uvms_mj.scenario.schema import Scenario, _controller_signature

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
            if robot != "paper":  # "<element>.<field>": checked on the model by each run's validation
                if len(rest) < 2:
                    raise SweepError(pre + f"{path}: expected {'.'.join(loc)}.<element>.<field> (an element name of "
                                     f"the {robot} model or the vehicle role, e.g. {'.'.join(loc)}.vehicle.added_mass)")
                return
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
        sections = [a for a in getattr(ann, "__args__", ()) if isinstance(a, type) and issubclass(a, BaseModel)]
        if sections:  # an optional section (X | None)
            ann = sections[0]
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            model = ann
            if not rest:
                raise SweepError(pre + f"{path} is a section; vary one of its fields: " + ", ".join(ann.model_fields))
            continue
        if rest:
            raise SweepError(pre + f"{'.'.join(loc)} is a value, not a section (got {path!r})")
        return


def parse_vary(item: str, controllers: Sequence[str] = ("rac", "rac_dob"), robot: str = "paper") -> Vary:
    """Parse and check ``KEY.PATH=SPEC`` (the key against the scenario schema for ``robot``, the
    spec's syntax and ranges). Values against the field's type are checked by :func:`plan_sweep`."""
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
        _check_path(p, controllers, text, robot)
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
    """The drawn value of every axis column, per sample (see "Samples" in :mod:`uvms_mj.analysis.sweep`)."""
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
    """An override key's value in a RobotParams (the inverse of params.apply_planar_overrides)."""
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
            from uvms_mj.scenario.schema import apply_scenario_sets, resolved, validate_scenario

            raw = apply_scenario_sets(self.base_raw, [f"controller.name={controller}"])
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
            if sc.robot != "paper":  # a model-file robot: the model's own value, as the factor x1
                return "x1"
            if parts[0] not in memo:
                if parts[0] == "nominal":
                    memo["nominal"] = nominal_params(sc)
                else:
                    from uvms_mj.plant.robot import compile_robot_spec

                    memo["plant"] = read_params(compile_robot_spec(models_dir() / "uvms.xml", plant_overrides(sc)))
            return _override_value(memo[parts[0]], name)
        node: Any = res
        for p in parts:
            node = node[p] if isinstance(node, dict) and p in node else None
        return copy.deepcopy(node)


def _factor_text(v: Any) -> float | None:
    """The factor of an override value written "xF" (a model-file robot's factor form), else None."""
    if isinstance(v, str) and v[:1] in ("x", "X"):
        try:
            return float(v[1:])
        except ValueError:
            return None
    return None


def _times(factor: Any, base: Any) -> Any:
    f0 = _factor_text(base)
    if f0 is not None:  # a factor of the model's value: the product, as a factor
        return f"x{float(factor) * f0!r}"
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
                        ok = (_is_num(b) or (isinstance(b, list) and b and all(_is_num(x) for x in b))
                              or _factor_text(b) is not None)
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
        apply_scenario_sets,
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
    varies = [parse_vary(v, names, base.robot) for v in vary]
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
                raw = apply_scenario_sets(base_raw, run_sets)
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
