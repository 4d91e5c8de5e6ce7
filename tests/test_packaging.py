"""One installed namespace: the wheel holds ``tfalda_sim`` only, and foreign top-level
``agents``, ``envs`` and ``tracks`` packages first on ``sys.path`` change nothing."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = str(Path(sys.executable).with_name("tfalda-sim"))


@pytest.fixture(scope="module")
def source_copy(tmp_path_factory: pytest.TempPathFactory) -> Path:
    # Built from a copy: setuptools leaves build/ in the source tree, and a stale
    # build/lib could smuggle removed modules into a later wheel.
    src = tmp_path_factory.mktemp("src") / "tfalda-sim"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(
        ".venv", ".git", "build", "out", "runs", "__pycache__", "*.egg-info", ".hypothesis",
        ".pytest_cache", ".ruff_cache"))
    return src


@pytest.fixture(scope="module")
def wheel_build(source_copy: Path,
                tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """The wheel ``pip wheel .`` builds, and what the build backend printed (``-v``: pip
    shows the backend's output, its warnings included, only when verbose)."""
    out = tmp_path_factory.mktemp("wheel")
    run = subprocess.run([sys.executable, "-m", "pip", "wheel", "-v", "--no-deps", "-w",
                          str(out), str(source_copy)], capture_output=True, text=True,
                         check=False)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    (whl,) = out.glob("tfalda_sim-*.whl")
    return whl, run.stdout + run.stderr


@pytest.fixture(scope="module")
def wheel(wheel_build: tuple[Path, str]) -> Path:
    return wheel_build[0]


DATA = {"tracks/data": "tfalda_sim/tracks/data", "tfalda_sim/camera/profiles":
        "tfalda_sim/camera/profiles", "agents/policies": "tfalda_sim/agents/policies"}
"""The data folders of the source tree and where they install."""


def test_the_build_declares_its_data_and_warns_of_nothing(wheel_build: tuple[Path, str]
                                                          ) -> None:
    """Data folders must be packages of the configuration with their package data: left
    out, setuptools warns for each (≈ 40 lines apiece, on every install) and a future
    setuptools would leave their files out."""
    whl, log = wheel_build
    assert "BuildBackendWarning" not in log and "absent from the" not in log, log[-4000:]
    with zipfile.ZipFile(whl) as zf:
        names = set(zf.namelist())
    for folder, installed in DATA.items():
        files = sorted(p.name for p in (ROOT / folder).iterdir()
                       if p.is_file() and not p.name.startswith("."))
        assert files, folder
        assert {f"{installed}/{f}" for f in files} <= names, (folder, sorted(names))


def test_the_editable_build_warns_of_nothing(source_copy: Path, tmp_path: Path) -> None:
    """``pip install -e .``'s build, run by the backend itself (installing would replace
    the environment's own editable install)."""
    code = ("import sys; from setuptools import build_meta as b; "
            "print(b.build_editable(sys.argv[1]))")
    run = subprocess.run([sys.executable, "-W", "always", "-c", code, str(tmp_path)],
                         cwd=source_copy, capture_output=True, text=True, check=False,
                         timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    log = run.stdout + run.stderr
    assert "BuildBackendWarning" not in log and "absent from the" not in log, log[-4000:]


def test_the_wheel_installs_one_top_level_package(wheel: Path) -> None:
    with zipfile.ZipFile(wheel) as zf:
        names = zf.namelist()
        tops = {n.split("/", 1)[0] for n in names}
        info = [n for n in names if n.endswith(".dist-info/top_level.txt")]
        top_level = zf.read(info[0]).decode().split() if info else []
    dist_info = {t for t in tops if t.endswith(".dist-info")}
    assert tops - dist_info == {"tfalda_sim"}
    assert top_level in ([], ["tfalda_sim"])
    # Every module of the source layout is in the wheel (a package missing from
    # pyproject's list would be left out silently).
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        from lint_imports import MAPPED
    finally:
        sys.path.remove(str(ROOT / "tools"))
    source = {f"tfalda_sim/{p.relative_to(ROOT / 'tfalda_sim').as_posix()}"
              for p in (ROOT / "tfalda_sim").rglob("*.py")}
    for name, folder in MAPPED.items():
        source |= {f"tfalda_sim/{name}/{p.relative_to(ROOT / folder).as_posix()}"
                   for p in (ROOT / folder).rglob("*.py")}
    assert source <= set(names), sorted(source - set(names))
    # The moved packages, their data and the entry point are all under tfalda_sim/.
    for name in ("tfalda_sim/tracks/model.py", "tfalda_sim/tracks/data/oval.json",
                 "tfalda_sim/envs/tfalda_track.py", "tfalda_sim/agents/pid.py",
                 "tfalda_sim/agents/policies/ppo.zip", "tfalda_sim/evaluation/lanes.xsd"):
        assert name in names, name


FOREIGN = {
    "agents": "MARK = 'the agents SDK'\n",
    "envs": "MARK = 'someone else\\'s envs'\n",
    "tracks": "MARK = 'a music library'\n",
}


def test_foreign_top_level_packages_do_not_shadow_ours(tmp_path: Path) -> None:
    for name, body in FOREIGN.items():
        (tmp_path / name).mkdir()
        (tmp_path / name / "__init__.py").write_text(body)
        # a module of the same name as one of ours, to catch a mixed-up import
        (tmp_path / name / "model.py").write_text("raise ImportError('foreign module')\n")
    env = dict(os.environ, PYTHONPATH=str(tmp_path))
    code = """
import agents, envs, tracks
assert (agents.MARK, envs.MARK, tracks.MARK) == ('the agents SDK', "someone else's envs",
                                               'a music library')
import gymnasium as gym
import tfalda_sim
env = gym.make("TfaldaTrack-v0", track="oval")
obs, _ = env.reset(seed=0)
for _ in range(5):
    obs, *_ = env.step(env.action_space.sample())
print(obs.shape[0])
"""
    run = subprocess.run([sys.executable, "-c", code], env=env, cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split()[-1] == "42"
    cli = subprocess.run([SCRIPT, "track", "generate", "--seed", "1", "--json"], env=env,
                         cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert cli.returncode == 0, cli.stderr
    assert json.loads(cli.stdout)["valid"] is True


def test_the_repository_folders_refuse_a_second_name() -> None:
    """With the repository root on sys.path `tracks` would import as a second copy of
    tfalda_sim.tracks (and poison numba's cache with that name): refused."""
    for name in ("tracks", "envs", "agents"):
        run = subprocess.run([sys.executable, "-c", f"import {name}"], cwd=ROOT,
                             capture_output=True, text=True, timeout=120)
        assert run.returncode != 0 and f"tfalda_sim.{name}; import it under that name" \
            in run.stderr, run.stderr


LINT = ROOT / "tools" / "lint_imports.py"


def _lint_with(tmp_path: Path, module: str, line: str) -> subprocess.CompletedProcess[str]:
    sys.path.insert(0, str(LINT.parent))
    try:
        from lint_imports import layout_tree
    finally:
        sys.path.remove(str(LINT.parent))
    pkg = layout_tree(tmp_path)
    if module:
        target = pkg / module
        target.write_text(target.read_text() + f"\n{line}\n")
    return subprocess.run([sys.executable, str(LINT), str(tmp_path)], capture_output=True,
                          text=True, timeout=300)


@pytest.mark.parametrize("module, line, broken", [
    ("", "", None),
    # an upward import: the camera (a low layer) reaching for the env
    ("camera/models.py", "from tfalda_sim.envs import TfaldaTrackEnv", "Layers"),
    # a cycle inside a package: the spatial index importing the track model back
    ("tracks/index.py", "from .model import Track", "No import cycles"),
    # the old top-level name of a moved package
    ("world.py", "import tracks", "One namespace"),
])
def test_the_import_contracts_catch_what_they_forbid(tmp_path: Path, module: str, line: str,
                                                     broken: str | None) -> None:
    run = _lint_with(tmp_path, module, line)
    if broken is None:
        assert run.returncode == 0 and "0 broken" in run.stdout, run.stdout
    else:
        assert run.returncode == 1, run.stdout
        assert f"{broken}" in run.stdout.split("Broken contracts")[-1], run.stdout
