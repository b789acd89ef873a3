"""The SPEC mini-language of ``--vary KEY.PATH=SPEC`` (grids, distributions, scale, per-component
lists; see :mod:`uvms_mj.analysis.sweep`): a tokenizer, a parser to a small tree and its
interpretation as :class:`Grid`, :class:`Random`, :class:`Scale` or :class:`Vector`."""

from __future__ import annotations

import copy
import difflib
import json
import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np
import yaml

#: Largest linspace(...) count (checked before anything is allocated).
MAX_GRID = 10_000


class SweepError(ValueError):
    """Bad sweep input (spec, key, range, controller, engine, out folder): the message names it."""


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
    """Parse a SPEC (see :mod:`uvms_mj.analysis.sweep`). Raises SweepError with the reason."""
    try:
        return _interpret(_parse_tree(str(text)))
    except _SpecSyntax as exc:
        raise SweepError(f"spec {text!r}: {exc}" + (f"; specs: {SPEC_HELP}" if exc.syntax else "")) from None


