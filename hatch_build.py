"""Hatch build hook: record the git commit of the tree a wheel is built from.

The wheel gets ``uvms_mj/_build_info.py`` with ``GIT_COMMIT`` (the commit, or "unknown" when
the source is not a git checkout, e.g. an sdist, or git is missing) and ``GIT_DIRTY`` (True,
False or None). :func:`uvms_mj.io.recorder.provenance` reads it when the package does not run from
a checkout of its own. Editable installs need nothing: they ask git directly.
"""

from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

from hatchling.builders.hooks.plugin.interface import BuildHookInterface


def _git(root: str, *args: str) -> str | None:
    try:
        out = subprocess.run(["git", "-C", root, *args], capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


class CustomBuildHook(BuildHookInterface):
    def initialize(self, version: str, build_data: dict) -> None:
        if version == "editable":
            return
        commit = _git(self.root, "rev-parse", "HEAD")
        # only this project's own repository, not one that happens to contain the sources
        top = _git(self.root, "rev-parse", "--show-toplevel")
        if not commit or not top or Path(top).resolve() != Path(self.root).resolve():
            commit, dirty = "unknown", None
        else:
            status = _git(self.root, "status", "--porcelain", "--untracked-files=no")
            dirty = None if status is None else bool(status)
        self._tmp = tempfile.TemporaryDirectory()
        path = Path(self._tmp.name) / "_build_info.py"
        path.write_text('"""Written by hatch_build.py when the wheel was built."""\n'
                        f"GIT_COMMIT = {commit!r}\nGIT_DIRTY = {dirty!r}\n")
        build_data["force_include"][str(path)] = "uvms_mj/_build_info.py"

    def finalize(self, version: str, build_data: dict, artifact_path: str) -> None:
        tmp = getattr(self, "_tmp", None)
        if tmp is not None:
            tmp.cleanup()
