"""MuJoCo's own warnings, routed.

MuJoCo's warnings (``mju_warning``: e.g. "Nan, Inf or huge value in QACC", or one raised while a
model compiles) go by default to stdout and to a ``MUJOCO_LOG.TXT`` in the current folder.
:func:`install_mujoco_warning_handler` routes them instead to stderr and to a per-process list
that the closed loop puts in its run's metadata (``RunResult.meta["mujoco_warnings"]``). Each
process (sweep workers included) installs its own handler: every model load
(:func:`uvms_mj.physics.model.compile_spec`, :func:`~uvms_mj.physics.model.load_spec`) and every
Plant does.
"""

from __future__ import annotations

import os
import sys
import threading

import mujoco

__all__ = ["install_mujoco_warning_handler", "mujoco_warnings"]

_MJ_WARNINGS: list[str] = []
#: At most this many warnings are kept per process between two reads (ours: enough to see a
#: pattern, bounded so a run that warns every step cannot grow memory).
_MJ_WARNINGS_MAX = 100
_mj_lock = threading.Lock()
_mj_handler_pid: int | None = None


def _on_mujoco_warning(msg: str) -> None:
    text = " ".join(str(msg).split())
    with _mj_lock:
        if len(_MJ_WARNINGS) < _MJ_WARNINGS_MAX:
            _MJ_WARNINGS.append(text)
    try:
        sys.stderr.write(f"mujoco warning: {text}\n")
    except Exception:  # noqa: BLE001 - a closed stderr must not break the simulation
        pass


def install_mujoco_warning_handler() -> None:
    """Route MuJoCo's warnings to stderr and :func:`mujoco_warnings` instead of MUJOCO_LOG.TXT
    (once per process)."""
    global _mj_handler_pid
    if _mj_handler_pid != os.getpid():
        mujoco.set_mju_user_warning(_on_mujoco_warning)
        _mj_handler_pid = os.getpid()


def mujoco_warnings(clear: bool = True) -> list[str]:
    """MuJoCo warnings seen in this process since the last call (with ``clear``)."""
    with _mj_lock:
        out = list(_MJ_WARNINGS)
        if clear:
            _MJ_WARNINGS.clear()
    return out
