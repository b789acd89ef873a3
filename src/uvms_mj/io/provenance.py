"""What a log records about the software that wrote it: package versions and the git commit."""

from __future__ import annotations

import platform
import subprocess
from importlib import metadata as _importlib_metadata
from pathlib import Path

import numpy as np


def _version(dist: str, module: str | None = None) -> str | None:
    try:
        return _importlib_metadata.version(dist)
    except Exception:
        pass
    if module:
        try:
            return str(__import__(module).__version__)
        except Exception:
            pass
    return None


def _git_info() -> dict:
    """Commit (and whether the tree is dirty) of the checkout this package runs from, else the
    one written into the wheel at build time (``uvms_mj/_build_info.py``, see ``hatch_build.py``),
    else ``{"git_commit": "unknown"}`` (never raises)."""
    info = _git_checkout_info()
    if info:
        return info
    try:
        from uvms_mj import _build_info  # type: ignore[attr-defined]

        commit = str(getattr(_build_info, "GIT_COMMIT", "") or "unknown")
        dirty = getattr(_build_info, "GIT_DIRTY", None)
        return {"git_commit": commit, **({"git_dirty": dirty} if isinstance(dirty, bool) else {})}
    except Exception:
        return {"git_commit": "unknown"}


def _git_checkout_info() -> dict:
    """Commit and dirtiness of the git checkout this package runs from; {} when it does not run
    from a git checkout of its own (an editable install), or git is missing (never raises)."""
    pkg = Path(__file__).resolve().parents[1]  # the uvms_mj package folder
    try:
        out = subprocess.run(["git", "-C", str(pkg), "rev-parse", "--show-toplevel", "HEAD"],
                             capture_output=True, text=True, timeout=5)
        if out.returncode != 0:
            return {}
        top, commit = out.stdout.split()
        top = Path(top).resolve()
        # Only the package's own repository (an editable install), not a repository that
        # happens to contain a site-packages directory.
        if pkg.parent.parent != top or not (top / "pyproject.toml").is_file():
            return {}
        info: dict = {"git_commit": commit}
        st = subprocess.run(["git", "-C", str(top), "status", "--porcelain", "--untracked-files=no"],
                            capture_output=True, text=True, timeout=5)
        if st.returncode == 0:
            info["git_dirty"] = bool(st.stdout.strip())
        return info
    except Exception:
        return {}


def provenance() -> dict:
    """Package versions and, when available, the git commit of the uvms_mj checkout."""
    from uvms_mj import __version__

    versions = {
        "uvms_mj": _version("uvms-mj") or __version__,
        "mujoco": _version("mujoco", "mujoco"),
        "numpy": np.__version__,
        "mcap": _version("mcap"),
        "python": platform.python_version(),
    }
    return {"versions": versions, **_git_info()}


