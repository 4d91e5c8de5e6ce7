"""The agents' commands' options as a user meets them through the console script: lists
without repeats, one range said once in the help and the check, every option with help."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cli_helpers import tfalda


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
    help_text = " ".join(tfalda(argv[0], "--help", cwd=tmp_path).out.split())
    options = help_text[help_text.index("options:"):]
    entry = options[options.index(f"{option} {option.strip('-').upper()}"):]
    assert entry.split(" --")[0].count(span) == 1, entry[:200]
