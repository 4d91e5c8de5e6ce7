"""The agents' commands' options as a user meets them through the console script: lists
without repeats, one range said once in the help and the check, every option with help."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cli_helpers import tfalda


def help_entry(help_text: str, option: str) -> str:
    """The text argparse's help gives ``option`` (e.g. "--laps LAPS"), its lines joined."""
    lines = help_text[help_text.index("\noptions:"):].splitlines()
    start = next(k for k, line in enumerate(lines) if line.strip().startswith(option + " ")
                 or line.strip() == option)
    entry = [lines[start].strip()[len(option):]]
    for line in lines[start + 1:]:
        if line.startswith("  -"):  # the next option
            break
        entry.append(line.strip())
    return " ".join(" ".join(entry).split())


@pytest.mark.parametrize("argv, message", [
    (["evaluate-agent", "--seeds", "0:1", "--speeds", "1.5,1.5"],
     "argument --speeds: 1.5 m/s is named twice: '1.5,1.5'"),
    (["evaluate-agent", "--seeds", "0:1", "--speeds", "1.5,2,1.50"],
     "argument --speeds: 1.5 m/s is named twice: '1.5,2,1.50'"),
    (["stress", "--seeds", "0:1", "--faults", "blackout,blackout"],
     "argument --faults: blackout is named twice: 'blackout,blackout'"),
])
def test_a_list_that_names_a_value_twice_is_refused(argv: list[str], message: str,
                                                    tmp_path: Path) -> None:
    """It ran each twice and pooled the runs with themselves (2 tracks, 2 successes for
    one track); refused as compare refuses --thesis straight,straight."""
    run = tfalda(*argv, "--out", tmp_path / "out", cwd=tmp_path, code=2)
    assert message in run.err, str(run)
    assert run.err.strip().splitlines()[-1].startswith("tfalda-sim "), str(run)
    assert not (tmp_path / "out").exists()


def test_the_python_api_refuses_repeated_speeds_and_faults() -> None:
    from tfalda_sim.agents.evaluate import iter_evaluate
    from tfalda_sim.agents.stress import check_fault_names

    with pytest.raises(ValueError, match="blackout is named twice"):
        check_fault_names(["blackout", "glare", "blackout"])
    with pytest.raises(ValueError, match=r"1\.5 m/s is named twice"):
        next(iter_evaluate("pid", range(1), speeds=(1.5, 1.5)))


@pytest.mark.parametrize("argv, option", [
    (["evaluate-agent", "--speeds", "0.01"], "--speeds"),
    (["evaluate-agent", "--speeds", "1.5,9"], "--speeds"),
    (["drive", "--speed", "0.01"], "--speed"),
    (["train", "--speed", "0.01"], "--speed"),
])
def test_a_speed_out_of_range_is_refused_with_the_range_the_help_gives(
        argv: list[str], option: str, tmp_path: Path) -> None:
    """The help said (0, top speed] while the check took [0.05, 8.3], and the error named
    --speeds twice ("argument --speeds: --speeds: …")."""
    from tfalda_sim.agents.command import TOP_SPEED_M_S
    from tfalda_sim.vehicle import MIN_CRUISE_SPEED_M_S

    span = f"[{MIN_CRUISE_SPEED_M_S:g}, {TOP_SPEED_M_S:g}]"
    error = tfalda(*argv, cwd=tmp_path, code=2).err.strip().splitlines()[-1]
    assert f"argument {option}: expected a number in {span} m/s" in error, error
    assert error.count(option) == 1, error
    entry = help_entry(tfalda(argv[0], "--help", cwd=tmp_path).out,
                       f"{option} {option.strip('-').upper()}")
    assert entry.count(span) == 1, entry


AGENT_COMMANDS = ("drive", "train", "stress", "evaluate-agent")


@pytest.mark.parametrize("command", AGENT_COMMANDS)
def test_every_option_has_help_with_its_default(command: str) -> None:
    """--agent, --laps, train --seed, … had no help text, and some defaults were not
    shown: every option says what it does, and one with a default names it."""
    import argparse

    from tests.cli_helpers import leaf_commands

    parser = leaf_commands()[(command,)]
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        name = action.option_strings[-1]
        assert action.help and action.help != argparse.SUPPRESS, f"{command} {name}: no help"
        if action.default not in (None, False):
            assert "default" in action.help, f"{command} {name}: default not shown"


@pytest.mark.parametrize("command, option, shown", [
    ("drive", "--agent {pid,ppo}", "(default: pid)"),
    ("drive", "--laps LAPS", "(default: 2)"),
    ("drive", "--speed SPEED", "(default: 1.5)"),
    ("evaluate-agent", "--agent {pid,ppo}", "(default: pid)"),
    ("evaluate-agent", "--laps LAPS", "(default: 3)"),
    ("evaluate-agent", "--speeds SPEEDS", "(default: 1.5)"),
    ("train", "--seed SEED", "(default: 0)"),
    ("train", "--timesteps TIMESTEPS", "(default: 1000000)"),
    ("stress", "--seeds SEEDS", "(default: 10000:10010)"),
    ("stress", "--out DIR", "(default: out/stress)"),
])
def test_the_help_shows_the_defaults(command: str, option: str, shown: str,
                                     tmp_path: Path) -> None:
    entry = help_entry(tfalda(command, "--help", cwd=tmp_path).out, option)
    assert shown in entry, entry


@pytest.mark.parametrize("command, option, words", [
    ("train", "--out DIR", "folder for the run"),
    ("stress", "--out DIR", "folder for stress.jsonl"),
    ("evaluate-agent", "--out F.json", "file"),
])
def test_the_help_says_whether_out_is_a_folder_or_a_file(command: str, option: str,
                                                         words: str, tmp_path: Path) -> None:
    """--out is a folder for train and stress and a file for evaluate-agent: the help's
    placeholder and text say which."""
    entry = help_entry(tfalda(command, "--help", cwd=tmp_path).out, option)
    assert words in entry, entry
