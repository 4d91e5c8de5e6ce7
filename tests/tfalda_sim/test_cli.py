"""The tfalda-sim command line (track commands)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tfalda_sim.cli import main
from tfalda_sim.tracks import generate, load_track


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_generate_json_and_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out, png = tmp_path / "t.json", tmp_path / "t.png"
    code, stdout, _ = run(capsys, "track", "generate", "--seed", "5", "--out", str(out),
                          "--png", str(png), "--json")
    assert code == 0
    summary = json.loads(stdout)
    for key in ("valid", "violations", "length_m", "min_centre_radius_m", "segments"):
        assert key in summary
    assert summary["valid"] is True and summary["violations"] == []
    track = generate(5)
    assert summary["length_m"] == pytest.approx(track.length_m)
    assert summary["segments"] == len(track.segments)
    assert load_track(out) == track
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_generate_refuses_to_overwrite(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    png = tmp_path / "t.png"
    png.write_bytes(b"keep me")
    out = tmp_path / "t.json"
    code, _, err = run(capsys, "track", "generate", "--seed", "1", "--out", str(out),
                       "--png", str(png))
    assert code == 2 and "--force" in err
    assert png.read_bytes() == b"keep me" and not out.exists()


def test_validate_reports_violations(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, stdout, _ = run(capsys, "track", "generate", "--seed", "2", "--out",
                          str(tmp_path / "t.json"), "--json")
    doc = json.loads((tmp_path / "t.json").read_text())
    doc["segments"][1]["radius_m"] = 0.9
    (tmp_path / "t.json").write_text(json.dumps(doc))
    code, stdout, _ = run(capsys, "track", "validate", str(tmp_path / "t.json"), "--json")
    assert code == 1
    summary = json.loads(stdout)
    assert summary["valid"] is False
    assert {"min_radius", "closure"} <= {v["rule"] for v in summary["violations"]}
    code, stdout, _ = run(capsys, "track", "validate", str(tmp_path / "t.json"))
    assert code == 1 and "segments[1].radius_m" in stdout


def test_validate_corrupt_file_is_a_clean_error(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    code, _, err = run(capsys, "track", "validate", str(bad))
    assert code == 2 and "not valid JSON" in err and "Traceback" not in err


def test_validate_named_track(capsys: pytest.CaptureFixture[str]) -> None:
    code, stdout, _ = run(capsys, "track", "validate", "figure-eight", "--json")
    assert code == 0 and json.loads(stdout)["intersections"] == 1


def test_list(capsys: pytest.CaptureFixture[str]) -> None:
    code, stdout, _ = run(capsys, "track", "list", "--json")
    assert code == 0 and json.loads(stdout)["tracks"][0]["name"] == "straight"


@pytest.mark.parametrize("argv", [
    ["track", "generate", "--seed", "1", "--colour", "red"],
    ["track", "generate", "--seed", "-4"],
    ["track", "generate", "--seed", "1", "--difficulty", "3"],
    ["track", "frobnicate"],
])
def test_unknown_or_bad_options_exit_2(argv: list[str], capsys) -> None:
    assert main(argv) == 2
    assert "error" in capsys.readouterr().err


def test_module_entry_point_runs() -> None:
    proc = subprocess.run([sys.executable, "-m", "tfalda_sim", "track", "list"],
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 0 and "figure-eight" in proc.stdout


def test_render_refuses_one_file_for_frame_and_truth(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "f.png"
    code, _, err = run(capsys, "render", "--track", "straight", "--s", "2", "--out", str(path),
                       "--truth", str(path))
    assert code == 2 and "same file" in err and not path.exists()


@pytest.mark.parametrize("option", ["--s", "--lateral", "--heading"])
def test_render_refuses_non_finite_numbers(option: str, tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    argv = {"--s": "2", "--lateral": "-0.2", "--heading": "0"}
    argv[option] = "nan"
    assert main(["render", "--track", "straight", "--out", str(tmp_path / "f.png"),
                 *[a for kv in argv.items() for a in kv]]) == 2
    assert "finite" in capsys.readouterr().err


def test_render_refuses_a_legal_but_unrenderable_track(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]
                                                       ) -> None:
    """A 249 m diagonal is within the track-file limits but over the raster's pixel cap:
    one error line, exit 2 (was an internal error)."""
    doc = {"format": "tfalda-sim/track", "version": 1, "name": "diag", "closed": False,
           "lane_width_m": 0.4, "start": {"x_m": 0, "y_m": 0, "heading_rad": 0.785},
           "start_line_s_m": None, "segments": [{"type": "straight", "length_m": 249}]}
    path = tmp_path / "diag.json"
    path.write_text(json.dumps(doc))
    code, _, err = run(capsys, "render", "--track", str(path), "--s", "1", "--out",
                       str(tmp_path / "f.png"))
    assert code == 2 and "cannot render this track" in err and "too large" in err
    assert not (tmp_path / "f.png").exists()


def test_version_through_the_console_script(tmp_path: Path) -> None:
    from importlib.metadata import version

    from tests.cli_helpers import tfalda

    run = tfalda("--version", cwd=tmp_path)
    assert run.out == f"tfalda-sim {version('tfalda-sim')}\n" and run.err == ""
    import tfalda_sim

    assert tfalda_sim.__version__ == version("tfalda-sim")
