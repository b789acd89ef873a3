"""The controllers by name: the built-ins (``rac``, ``rac_dob``, ``pd``, ``station_pid``,
``task_priority``, registered with :func:`uvms_mj.control.base.register` when their modules are
imported, which the functions here do on first use) and third parties' through the entry-point
group :data:`uvms_mj.control.base.ENTRY_POINT_GROUP`.
"""

from __future__ import annotations

from importlib import metadata
from typing import Any

from uvms_mj.control.base import _REGISTRY, ENTRY_POINT_GROUP, Controller, ControllerError

__all__ = ["RETIRED", "available", "create", "factory", "unknown_message"]

#: Controller names that no longer exist in the product -> the one to use instead (the planar
#: closed-form RAC of the first reproduction is a test oracle since issue 18; ``rac`` / ``rac_dob``
#: give the same run on the paper's robot, to 1e-12).
RETIRED = {"rac_planar": "rac", "rac_dob_planar": "rac_dob"}


def unknown_message(name: str) -> str:
    """Why ``name`` is not a controller, in one line: a retired name and what replaces it, or
    the registered names (with a did-you-mean)."""
    import difflib

    if name in RETIRED:
        return (f"controller {name!r} is no longer shipped (the planar closed form is a test oracle now): use "
                f"{RETIRED[name]!r}, which gives the same run on the paper's robot")
    names = available()
    close = difflib.get_close_matches(str(name), names, n=1, cutoff=0.6)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    return f"unknown controller {name!r}{hint}; registered: {', '.join(names)}"


def _builtins() -> None:
    from uvms_mj.control import pd, rac, station_pid, task_priority  # noqa: F401  (registers the built-ins)


def _entry_points() -> dict[str, metadata.EntryPoint]:
    return {ep.name: ep for ep in metadata.entry_points(group=ENTRY_POINT_GROUP)}


def available() -> list[str]:
    """Names of the built-in and installed (entry-point) controllers."""
    _builtins()

    return sorted(set(_REGISTRY) | set(_entry_points()))


def factory(name: str):
    """The class (or factory) registered as ``name``.

    Raises:
        ControllerError: unknown name (the message lists the registered controllers)."""
    _builtins()
    f = _REGISTRY.get(name)
    if f is None:
        ep = _entry_points().get(name)
        if ep is None:
            raise ControllerError(unknown_message(name))
        f = ep.load()
    return f


def create(name: str, **kwargs: Any) -> Controller:
    """Create a controller by name.

    Raises:
        ControllerError: unknown name (the message lists the registered controllers).
    """
    ctrl = factory(name)(**kwargs)
    if not getattr(ctrl, "name", ""):
        try:  # the registry name goes into every log (a plug-in need not set it)
            ctrl.name = name
        except (AttributeError, TypeError):
            pass
    return ctrl
