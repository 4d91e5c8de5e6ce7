"""A drive stopped before its first step: no figure to report is null in --json (strict
JSON) and "n/a" in the table, not NaN and not 0.0 cm."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from tests.cli_helpers import tfalda
from tfalda_sim.cli import main

SITECUSTOMIZE = '''
import os
import signal

from tfalda_sim.envs.tfalda_track import TfaldaTrackEnv

_step = TfaldaTrackEnv.step


def step(self, action):
    # A Ctrl-C before the drive's first step: the step never happens.
    os.kill(os.getpid(), signal.SIGINT)
    return _step(self, action)


TfaldaTrackEnv.step = step
'''
"""Started with the console script (on its PYTHONPATH): the Ctrl-C lands as the first step
begins."""


def _ctrl_c_at_the_first_step(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(SITECUSTOMIZE)
    monkeypatch.setenv("PYTHONPATH", str(hook))


NO_FIGURES = ("mean_abs_cross_track_m", "max_abs_cross_track_m", "mean_hit_rate")


def test_drive_json_stopped_before_the_first_step_is_strict_json_with_nulls(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _ctrl_c_at_the_first_step(monkeypatch, tmp_path)
    run = tfalda("drive", "--track", "oval", "--laps", "1", "--json", cwd=tmp_path, code=130)
    doc = run.json()  # strict: NaN is refused
    assert doc["steps"] == 0 and doc["ended"] == "interrupted"
    assert all(doc[key] is None for key in NO_FIGURES), doc


def test_drive_table_stopped_before_the_first_step_says_n_a(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _ctrl_c_at_the_first_step(monkeypatch, tmp_path)
    run = tfalda("drive", "--track", "oval", "--laps", "1", cwd=tmp_path, code=130)
    assert "mean |cross-track error| n/a" in run.out, run.out
    assert "mean hit rate n/a" in run.out and "nan" not in run.out.lower(), run.out
    assert "0.0 cm" not in run.out, run.out


def test_a_drive_of_no_step_reports_no_figures(monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """From Python: the result's figures are NaN (no step, no mean), the --json output of
    the command null."""
    from tfalda_sim.agents.drive import drive
    from tfalda_sim.agents.pid import LanePid
    from tfalda_sim.envs.tfalda_track import TfaldaTrackEnv
    from tfalda_sim.tracks import generate

    def stopped(self: TfaldaTrackEnv, action: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(TfaldaTrackEnv, "step", stopped)
    result = drive(LanePid(), generate(7), laps=1)
    assert result.steps == 0 and result.ended == "interrupted"
    assert all(math.isnan(getattr(result, key)) for key in NO_FIGURES)
    main(["drive", "--track", "oval", "--laps", "1", "--json"])
    doc = json.loads(capsys.readouterr().out,
                     parse_constant=lambda name: pytest.fail(f"{name} is not JSON"))
    assert all(doc[key] is None for key in NO_FIGURES), doc
