"""Outputs are checked before any work and written all or none (tfalda_sim.outputs), and
every command that writes files refuses a bad output before it starts its work."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tfalda_sim.cli import main
from tfalda_sim.outputs import DIRECTORY, Output, OutputError, Outputs, check_outputs, staged


def bad_outputs(tmp_path: Path, suffix: str) -> dict[str, tuple[Path, str]]:
    """Paths no command can write, with the words its error must contain. Tests run as
    root, where permission bits do not stop a write: a path under a regular file, a
    folder given for a file and the read-only /proc are unwritable for everyone."""
    a_file = tmp_path / "plain.txt"
    a_file.write_text("x")
    folder = tmp_path / f"folder{suffix}"
    folder.mkdir()
    return {
        "under a file": (a_file / f"x{suffix}", "is a file, not a folder"),
        "a folder": (folder, "is a folder"),
        "read-only /proc": (Path(f"/proc/tfalda-sim-test{suffix}"), "cannot write in /proc"),
    }


@pytest.mark.parametrize("case", ["under a file", "a folder", "read-only /proc"])
def test_unwritable_outputs_are_refused_naming_the_option(tmp_path: Path, case: str) -> None:
    path, words = bad_outputs(tmp_path, ".png")[case]
    with pytest.raises(OutputError, match="--png") as exc:
        check_outputs([Output("--png", path, ".png")], force=True)
    assert words in str(exc.value)


def test_suffix_existing_inputs_and_duplicates(tmp_path: Path) -> None:
    target = tmp_path / "a.png"
    with pytest.raises(OutputError, match=r"must end in \.png"):
        check_outputs([Output("--png", tmp_path / "a.jpg", ".png")], force=False)
    target.write_bytes(b"old")
    with pytest.raises(OutputError, match="add --force"):
        check_outputs([Output("--png", target, ".png")], force=False)
    check_outputs([Output("--png", target, ".png")], force=True)
    with pytest.raises(OutputError, match="is the --track input"):
        check_outputs([Output("--png", target, ".png")], force=True, inputs={"--track": target})
    with pytest.raises(OutputError, match="same file"):
        check_outputs([Output("--a", tmp_path / "b.png", ".png"),
                       Output("--b", tmp_path / "." / "b.png", ".png")], force=True)
    # A folder output: its files need --force, a file in its place is refused.
    (tmp_path / "rep").mkdir()
    (tmp_path / "rep" / "r.json").write_text("{}")
    with pytest.raises(OutputError, match="add --force"):
        check_outputs([Output("--out", tmp_path / "rep", DIRECTORY)], force=False,
                      files_in={"--out": ["r.json", "r.md"]})
    with pytest.raises(OutputError, match="is a file; give a folder"):
        check_outputs([Output("--out", target, DIRECTORY)], force=True)
    # The probe file used for the writability check is gone again.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png", "rep"]


def test_outputs_commit_all_or_remove_everything(tmp_path: Path) -> None:
    a, b = tmp_path / "new" / "deep" / "a.json", tmp_path / "b.png"
    b.write_bytes(b"old")
    with pytest.raises(RuntimeError), Outputs() as outs:
        outs.path(a).write_text("{}")
        outs.path(b).write_bytes(b"new")
        raise RuntimeError("the second writer failed")
    # Nothing of the failed command is left: no temporary file, no created folder.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.png"]
    assert b.read_bytes() == b"old"
    with staged(a, None, b) as (ta, none, tb):
        assert none is None and ta.suffix == ".json" and tb.suffix == ".png"
        ta.write_text("{}")
        tb.write_bytes(b"new")
    assert a.read_text() == "{}" and b.read_bytes() == b"new"
    assert sorted(p.name for p in a.parent.iterdir()) == ["a.json"]


def _forbid(monkeypatch: pytest.MonkeyPatch, target: str) -> None:
    """Make ``target`` (module.attr) fail the test if the command gets as far as its work."""
    def refuse(*_: object, **__: object) -> None:
        raise AssertionError(f"{target} ran although an output was unwritable")
    monkeypatch.setattr(target, refuse)


COMMANDS = {
    # command → (argv before the output option, the option, its suffix, the work it must
    # not reach)
    "track generate --out": (["track", "generate", "--seed", "1"], "--out", ".json",
                             "tfalda_sim.tracks.command.generate"),
    "track generate --png": (["track", "generate", "--seed", "1"], "--png", ".png",
                             "tfalda_sim.tracks.command.generate"),
    "render --out": (["render", "--track", "oval", "--s", "1"], "--out", ".png",
                     "tfalda_sim.rendering.Renderer"),
    "render --truth": (["render", "--track", "oval", "--s", "1", "--out", "{tmp}/ok.png"],
                       "--truth", ".png", "tfalda_sim.rendering.Renderer"),
    "drive --video": (["drive", "--track", "oval"], "--video", ".mp4",
                      "tfalda_sim.agents.drive.drive"),
    "drive --camera-video": (["drive", "--track", "oval"], "--camera-video", ".mp4",
                             "tfalda_sim.agents.drive.drive"),
    "stress --out": (["stress", "--seeds", "1:2"], "--out", "",
                     "tfalda_sim.agents.stress.battery_jobs"),
    "evaluate --plot": (["evaluate", "--scenario", "straight"], "--plot", ".png",
                        "tfalda_sim.evaluation.command.run_scenario"),
    "evaluate --xml": (["evaluate", "--scenario", "straight"], "--xml", ".xml",
                       "tfalda_sim.evaluation.command.run_scenario"),
    "evaluate --jsonl": (["evaluate", "--scenario", "random", "--seeds", "1:3"], "--jsonl",
                         ".jsonl", "tfalda_sim.evaluation.sweep.seed_job"),
    "evaluate --video": (["evaluate", "--scenario", "straight"], "--video", ".mp4",
                         "tfalda_sim.evaluation.command.run_scenario"),
    "compare --out": (["compare", "--no-generated"], "--out", "",
                      "tfalda_sim.evaluation.baseline.compare_jobs"),
    "evaluate-agent --out": (["evaluate-agent", "--seeds", "1:2"], "--out", ".json",
                             "tfalda_sim.agents.evaluate.evaluation_jobs"),
    "train --out": (["train", "--timesteps", "10"], "--out", "", "tfalda_sim.agents.train.train"),
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
@pytest.mark.parametrize("case", ["under a file", "read-only /proc"])
def test_every_command_refuses_an_unwritable_output_before_any_work(
        command: str, case: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    argv, option, suffix, work = COMMANDS[command]
    _forbid(monkeypatch, work)
    path, words = bad_outputs(tmp_path, suffix)[case]
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    code = main([*argv, option, str(path), "--force"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.startswith("error: ") and option in err and words in err
    assert "Traceback" not in err
    assert not (tmp_path / "ok.png").exists()


def test_track_generate_writes_both_files_or_neither(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]
                                                     ) -> None:
    # The reproduction: --out was written, then --png failed.
    ok, bad = tmp_path / "ok.json", tmp_path / "plain.txt" / "p.png"
    (tmp_path / "plain.txt").write_text("x")
    assert main(["track", "generate", "--seed", "1", "--out", str(ok), "--png", str(bad)]) == 2
    assert not ok.exists()
    assert main(["track", "generate", "--seed", "1", "--out", str(ok), "--png",
                 str(tmp_path / "p.png"), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["out"] == str(ok) and ok.exists() and (tmp_path / "p.png").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok.json", "p.png", "plain.txt"]


def test_an_output_may_not_replace_an_input(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    """An input whose name has the output's suffix: the input check itself must refuse."""
    policy = tmp_path / "policy.mp4"  # --policy takes any name; --video wants .mp4
    policy.write_bytes(b"not a video")
    code = main(["drive", "--agent", "ppo", "--policy", str(policy), "--video", str(policy),
                 "--force"])
    assert code == 2 and "is the --policy input" in capsys.readouterr().err
    assert policy.read_bytes() == b"not a video"
    track = tmp_path / "t.json"
    assert main(["track", "generate", "--seed", "2", "--out", str(track)]) == 0
    capsys.readouterr()
    out = tmp_path / "f.png"
    check_outputs([Output("--out", out, ".png")], force=True, inputs={"--track": track})
    with pytest.raises(OutputError, match="is the --track input"):
        check_outputs([Output("--out", track, ".json")], force=True, inputs={"--track": track})


def test_a_name_too_long_for_the_file_system_is_refused_first(tmp_path: Path) -> None:
    with pytest.raises(OutputError, match="longer than the"):
        check_outputs([Output("--plot", tmp_path / ("a" * 300 + ".png"), ".png")], force=True)
    # a long name that fits still passes, its temporary name too (short, fixed length)
    check_outputs([Output("--plot", tmp_path / ("a" * 248 + ".png"), ".png")], force=True)


def test_a_journal_grows_under_a_fixed_name_and_becomes_its_target(tmp_path: Path) -> None:
    from tfalda_sim.outputs import journal_of

    target = tmp_path / "sub" / "r.jsonl"
    outs = Outputs()
    journal = outs.journal(target)
    assert journal == journal_of(target) == tmp_path / "sub" / "r.jsonl.partial"
    journal.write_text("header\n")
    assert outs.commit() == [target] and target.read_text() == "header\n"
    assert not journal.exists()


@pytest.mark.parametrize("resumed", [False, True])
def test_an_aborted_journal_goes_unless_it_was_resumed(tmp_path: Path, resumed: bool) -> None:
    target = tmp_path / "r.jsonl"
    with pytest.raises(RuntimeError), Outputs() as outs:
        outs.journal(target, keep_on_abort=resumed).write_text("header\nrecord\n")
        raise RuntimeError("a job failed")
    assert (tmp_path / "r.jsonl.partial").exists() is resumed
    assert not target.exists()
