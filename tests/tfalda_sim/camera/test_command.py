"""``tfalda-sim camera``'s errors name the argument as the user gave it."""

from __future__ import annotations

from pathlib import Path

from tests.cli_helpers import tfalda


def test_camera_show_names_its_positional_not_an_option(tmp_path: Path) -> None:
    (tmp_path / "bad.yaml").write_text("format: tfalda-sim-camera/1\nlens: [\n")
    for spec, says in (("bad.yaml", "bad.yaml: not valid YAML"),
                       ("sony", "unknown camera 'sony'")):
        run = tfalda("camera", "show", spec, cwd=tmp_path, code=2)
        assert run.err.startswith(f"error: argument camera: {spec}" if spec == "bad.yaml"
                                  else "error: argument camera: unknown camera"), str(run)
        assert says in run.err and "--camera" not in run.err, str(run)
    # the option keeps its name
    drive = tfalda("drive", "--camera", "bad.yaml", cwd=tmp_path, code=2)
    assert drive.err.startswith("error: --camera: bad.yaml: not valid YAML"), str(drive)
