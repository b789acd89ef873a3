"""The models/ layout (mujoco_menagerie's convention, models/README.md): one folder per robot with
its README; built-in names resolve into them; a scene adds only visual elements to its robot;
models/uvms.xml is paper/uvms.xml; every document the README, docs/ or a model file cites is in
the repository.

Independent truths: the files on disk, the robot file compiled on its own (for its scene and
for models/uvms.xml), and MuJoCo's forward dynamics of each.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import mujoco
import numpy as np
import pytest

import uvms_mj  # noqa: F401  (registers the uvms plugins)
from uvms_mj.plant.plant import default_model_path, models_dir
from uvms_mj.plant.files import BUILTIN_ROBOTS, robot_path

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "models"
FOLDERS = ("paper", "bluerov2_heavy", "alpha_arm", "bluerov2_alpha", "hinsdale2023")
#: scene -> its robot file, in the same folder
SCENES = {"paper": "uvms.xml", "bluerov2_heavy": "bluerov2_heavy.xml", "bluerov2_alpha": "bluerov2_alpha.xml"}


def test_one_folder_per_robot_with_readme():
    assert models_dir() == MODELS  # in a checkout
    assert sorted(p.name for p in MODELS.iterdir() if p.is_dir()) == sorted(FOLDERS)
    assert sorted(p.name for p in MODELS.iterdir() if p.is_file()) == ["README.md", "uvms.xml"]
    for name in FOLDERS:
        assert (MODELS / name / "README.md").is_file(), name
    for name, rel in BUILTIN_ROBOTS.items():
        path = robot_path(name)
        assert path.is_file() and path.parent == MODELS / name, (name, rel)
    assert default_model_path() == MODELS / "paper" / "scene.xml" == robot_path("paper")
    wheel = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["hatch"]["build"]["targets"]["wheel"]
    assert wheel["force-include"]["models"] == "uvms_mj/models"  # the whole tree, sub-folders included


def _forward(m: mujoco.MjModel) -> np.ndarray:
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0) if m.nkey else mujoco.mj_resetData(m, d)
    d.qvel[:] = 0.1 * np.arange(1, m.nv + 1) / m.nv  # moving: drag, Coriolis and added-mass terms act
    mujoco.mj_forward(m, d)
    return d.qacc.copy()


@pytest.mark.parametrize("name", sorted(SCENES))
def test_scene_adds_only_visuals(name):
    robot = mujoco.MjModel.from_xml_path(str(MODELS / name / SCENES[name]))
    scene = mujoco.MjModel.from_xml_path(str(MODELS / name / "scene.xml"))
    for attr in ("nq", "nv", "nu", "na", "nbody", "njnt", "nsite", "nplugin", "nkey"):
        assert getattr(scene, attr) == getattr(robot, attr), attr
    np.testing.assert_array_equal(scene.body_mass, robot.body_mass)
    assert scene.opt.timestep == robot.opt.timestep and scene.opt.integrator == robot.opt.integrator
    robot_geoms = {robot.geom(i).name for i in range(robot.ngeom)}
    extra = [i for i in range(scene.ngeom) if scene.geom(i).name not in robot_geoms]
    assert extra, "a scene adds a floor"
    for i in extra:  # visual only: collides with nothing
        assert scene.geom_contype[i] == 0 and scene.geom_conaffinity[i] == 0, scene.geom(i).name
    assert scene.nlight >= 1 and scene.ncam >= 1
    np.testing.assert_allclose(_forward(scene), _forward(robot), rtol=1e-12, atol=1e-12)


def test_top_level_uvms_is_the_paper_robot():
    """models/uvms.xml holds no number: it compiles to the model of paper/uvms.xml."""
    def saved(path: Path) -> bytes:
        m = mujoco.MjModel.from_xml_path(str(path))
        buf = np.zeros(mujoco.mj_sizeModel(m), np.uint8)
        mujoco.mj_saveModel(m, None, buf)
        return bytes(buf)

    assert saved(MODELS / "uvms.xml") == saved(MODELS / "paper" / "uvms.xml")
    assert not re.search(r"\d\.\d", re.sub(r"<!--.*?-->", "", (MODELS / "uvms.xml").read_text(), flags=re.S))


# A reference: a path starting with ../ (relative to the citing file), a repository path
# (docs/, models/, ...: relative to the root) or a Markdown link target (relative to the file).
_TOKEN = re.compile(r"(?<![\w./-])((?:\.\./)+[\w.-][\w./-]*|(?:docs|models|tests|benchmarks|scenarios|src|data)/[\w./-]*)")
_LINK = re.compile(r"\]\(([^)#\s]+)")
#: The Hinsdale 2023 trial data ship as data/hinsdale-2023 with their own change; until then the
#: references into it are not checked, and README.md's command examples may still name the
#: data's location outside the repository.
_POOL_DATA = "data/hinsdale-2023"
_POOL_DATA_OUTSIDE = "../shared/data/hinsdale-2023"


def _citing_files() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted(MODELS.rglob("README.md")),
            *sorted(MODELS.rglob("*.xml"))]


def _references(path: Path) -> set[tuple[str, Path]]:
    text = path.read_text()
    refs = set()
    for m in _TOKEN.finditer(text):
        if m.end() < len(text) and text[m.end()] in "*<{":  # a pattern (models/*/README.md), not a path
            continue
        tok = m.group(1).rstrip(".,;:)")
        refs.add((tok, (path.parent if tok.startswith("..") else ROOT) / tok))
    for m in _LINK.finditer(text):
        if "://" not in m.group(1):
            refs.add((m.group(1), path.parent / m.group(1)))
    return refs


def test_every_cited_document_is_in_the_repository():
    missing = []
    for f in _citing_files():
        for tok, target in sorted(_references(f)):
            target = target.resolve()
            if f.name == "README.md" and f.parent == ROOT and tok.startswith(_POOL_DATA_OUTSIDE):
                continue
            if not target.is_relative_to(ROOT):
                missing.append(f"{f.relative_to(ROOT)}: {tok} (outside the repository)")
            elif not target.exists() and not (tok.startswith("data/") and not (ROOT / _POOL_DATA).exists()):
                missing.append(f"{f.relative_to(ROOT)}: {tok}")
    assert not missing, "\n".join(missing)


def test_no_citation_of_outside_copies():
    """The design notes are cited in docs/, the paper by its reference (its text is not shipped)."""
    for f in _citing_files():
        text = f.read_text()
        assert "seed/" not in text, f
        if f.parent != ROOT:
            assert "shared/" not in text, f
