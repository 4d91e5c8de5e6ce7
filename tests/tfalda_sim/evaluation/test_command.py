"""``tfalda-sim evaluate``: outputs, JSON, and bad input (exit code 2)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import pytest

from tfalda_sim.cli import main
from tfalda_sim.evaluation.export import read_jsonl, read_lanes_xml


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_straight_drive_writes_every_output(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    files = {k: tmp_path / f"out.{s}" for k, s in
             (("plot", "png"), ("xml", "xml"), ("jsonl", "jsonl"), ("video", "mp4"))}
    args = [a for k, p in files.items() for a in (f"--{k}", str(p))]
    code, out, _ = run(capsys, "evaluate", "--scenario", "straight", "--json", *args)
    assert code == 0
    summary = json.loads(out)
    assert set(summary["summary"]) == {"with LIS", "without LIS"}
    for s in summary["summary"].values():
        assert s["frames"] == 80 and 0.0 <= s["mean_confidence"] <= 1.0
    assert len(read_lanes_xml(files["xml"])) == 80
    assert len(read_jsonl(files["jsonl"])) == 160 == summary["jsonl_lines"]
    cap = cv2.VideoCapture(str(files["video"]))
    assert cap.get(cv2.CAP_PROP_FRAME_COUNT) == 80
    assert cv2.imread(str(files["plot"])) is not None
    # the same command again: refused without --force, the files stay
    before = files["xml"].read_bytes()
    code, _, err = run(capsys, "evaluate", "--scenario", "straight", "--xml", str(files["xml"]))
    assert code == 2 and "--force" in err and files["xml"].read_bytes() == before


def test_random_seeds_and_ablation(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "evaluate", "--scenario", "random", "--seeds", "2:4",
                       "--max-frames", "12", "--workers", "1", "--json",
                       "--plot", str(tmp_path / "s.png"))
    assert code == 0
    summary = json.loads(out)
    assert [(s["seed"], s["run"]) for s in summary["per_seed"]] == [
        (2, "with LIS"), (2, "without LIS"), (3, "with LIS"), (3, "without LIS")]
    assert summary["pooled"]["with LIS"]["frames"] == 24
    code, out, _ = run(capsys, "evaluate", "--scenario", "random", "--seeds", "2:3",
                       "--max-frames", "8", "--ablation", "--plot", str(tmp_path / "a.png"))
    assert code == 0 and "without vertical" in out and "only min_max" in out
    assert (tmp_path / "a.png").exists()


@pytest.mark.parametrize("argv, message", [
    (["--scenario", "random"], "needs --seeds"),
    (["--scenario", "straight", "--seeds", "0:3"], "only applies to --scenario random"),
    (["--scenario", "random", "--seeds", "0:3", "--xml", "x.xml"], "single seed"),
    (["--scenario", "straight", "--ablation", "--no-lis"], "not allowed with argument"),
    (["--scenario", "straight", "--plot", "chart.jpg"], "must end in .png"),
    (["--scenario", "straight", "--epsilon-px", "-1"], "--epsilon-px"),
])
def test_bad_input_exits_2_with_the_reason(argv: list[str], message: str, tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str],
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    code, _, err = run(capsys, "evaluate", *argv)
    assert code == 2 and message in err


@pytest.mark.parametrize("argv", [["--scenario", "bend"], ["--scenario", "random", "--seeds",
                                                           "5:2"], ["--speed", "-1"],
                                  ["--scenario", "straight", "--epsilon-px", "nan"]])
def test_argparse_rejects_unknown_values(argv: list[str],
                                         capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["evaluate", *argv]) == 2


@pytest.mark.parametrize("argv, message", [
    # The reproductions: ValueError tracebacks before.
    (["--scenario", "straight", "--speed", "1e9"], "the car's top speed"),
    (["--scenario", "straight", "--stride", "1000000"], "expected an integer from 1 to 50"),
    (["--scenario", "random", "--seeds", "0:2", "--stride", "1000000"], "from 1 to 50"),
    (["--scenario", "straight", "--stride", "3"], "does not fit the thesis' straight drive"),
    (["--scenario", "straight", "--epsilon-px", "1e9"], "--epsilon-px"),
    (["--scenario", "straight", "--ablation", "--no-lis"], "not allowed with argument"),
])
def test_bad_values_exit_2_with_the_usage(argv: list[str], message: str,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(capsys, "evaluate", *argv)
    assert code == 2 and "usage: tfalda-sim evaluate" in err and message in err
    assert "Traceback" not in err
