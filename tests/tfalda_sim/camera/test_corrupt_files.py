"""Corrupt OpenCV calibration files (truncated, empty, binary, a broken matrix, missing
nodes) are refused with one line naming the file and the problem: through the API, the
gymnasium env and every command that reads a camera."""

from __future__ import annotations

from pathlib import Path

import gymnasium
import pytest

from tests.cli_helpers import tfalda
from tfalda_sim.camera import CameraFileError, CameraMount, load_camera, load_intrinsics

TRUNCATED_XML = '<?xml version="1.0"?>\n<opencv_storage>\n'
HEAD = TRUNCATED_XML
TAIL = "</opencv_storage>\n"
K = ('<camera_matrix type_id="opencv-matrix"><rows>3</rows><cols>3</cols><dt>d</dt>'
     "<data>300. 0. 376. 0. 300. 240. 0. 0. 1.</data></camera_matrix>")
D = ('<distortion_coefficients type_id="opencv-matrix"><rows>4</rows><cols>1</cols><dt>d</dt>'
     "<data>0. 0. 0. 0.</data></distortion_coefficients>")
SIZE = "<image_width>752</image_width><image_height>480</image_height>"
OPENCV_YAML = "%YAML:1.0\n---\n"

CORRUPT = {
    "truncated": ("cam.xml", TRUNCATED_XML, r"not a valid OpenCV FileStorage file \(line 2"),
    "header only": ("cam.xml", '<?xml version="1.0"?>\n', "not a valid OpenCV FileStorage"),
    "foreign root": ("cam.xml", '<?xml version="1.0"?>\n<foo/>\n',
                     "<opencv_storage> tag is missing"),
    "unclosed": ("cam.xml", HEAD + K, "not a valid OpenCV FileStorage file"),
    "control bytes": ("cam.xml", HEAD + "\x00\x01\x02" + TAIL, "not a valid OpenCV"),
    "truncated yaml": ("cam.yaml", OPENCV_YAML + "camera_matrix: !!opencv-matrix\n   rows: 3\n"
                       "   cols: 3\n   dt: d\n   data: [ 1.", "line 7: Missing ,"),
    "tabs": ("cam.yaml", OPENCV_YAML + "\tcamera_matrix: 3\n", "Tabs are prohibited"),
    "empty yaml": ("cam.yaml", "%YAML:1.0\n", "an empty OpenCV FileStorage file"),
    "empty xml": ("cam.xml", HEAD + TAIL, "an empty OpenCV FileStorage file"),
    "a list": ("cam.yaml", OPENCV_YAML + "- 1\n- 2\n", "top level is not a mapping"),
    "no matrix": ("cam.xml", HEAD + D + SIZE + TAIL, "no camera_matrix matrix"),
    "scalar matrix": ("cam.xml", HEAD + "<camera_matrix>5</camera_matrix>" + D + SIZE + TAIL,
                      "camera_matrix is not an opencv-matrix"),
    "short data": ("cam.xml", HEAD + K.replace("0. 0. 1.</data>", "</data>") + D + SIZE + TAIL,
                   r"camera_matrix.data must hold rows × cols = 9 numbers, got 6"),
    "bad dt": ("cam.xml", HEAD + K.replace("<dt>d</dt>", "<dt>zz</dt>") + D + SIZE + TAIL,
               "camera_matrix.dt must be d or f"),
    "no dt": ("cam.xml", HEAD + K.replace("<dt>d</dt>", "") + D + SIZE + TAIL,
              "camera_matrix.dt is missing"),
    "huge rows": ("cam.xml", HEAD + K.replace("<rows>3</rows>", "<rows>99999999999</rows>") + D
                  + SIZE + TAIL, r"camera_matrix.rows must be an integer in \[1, 16\]"),
    "text data": ("cam.xml", HEAD + K.replace("300. 0. 376.", "a b c") + D + SIZE + TAIL,
                  r"camera_matrix.data\[0\] must be a number, got 'a'"),
    "text width": ("cam.xml", HEAD + K + D + SIZE.replace("752", "wide") + TAIL,
                   r"image_width must be an integer in \[64, 8192\], got wide"),
    "no width": ("cam.xml", HEAD + K + D + TAIL, "no image_width"),
}


@pytest.mark.parametrize("case", list(CORRUPT))
def test_corrupt_opencv_files_are_refused_naming_the_problem(tmp_path: Path, case: str) -> None:
    name, text, match = CORRUPT[case]
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    with pytest.raises(CameraFileError, match=match) as err:
        load_camera(path, mount=CameraMount())
    assert str(err.value).startswith(f"{path}: ") and "\n" not in str(err.value)
    with pytest.raises(CameraFileError, match=match):
        load_intrinsics(path)


def test_the_env_refuses_a_truncated_xml_camera(tmp_path: Path) -> None:
    bad = tmp_path / "bad.xml"
    bad.write_text(TRUNCATED_XML, encoding="utf-8")
    with pytest.raises(ValueError, match=r"bad.xml: not a valid OpenCV FileStorage file"):
        gymnasium.make("tfalda_sim:TfaldaTrack-v0", camera=str(bad))


def test_commands_refuse_a_truncated_xml_camera(tmp_path: Path) -> None:
    (tmp_path / "bad.xml").write_text(TRUNCATED_XML, encoding="utf-8")
    (tmp_path / "empty.xml").write_text("", encoding="utf-8")
    frame = Path(__file__).parents[3] / "docs" / "cameras" / "reference-car-fit.png"
    runs = [tfalda("camera", "show", "bad.xml", cwd=tmp_path, code=2),
            tfalda("drive", "--camera", "bad.xml", cwd=tmp_path, code=2),
            tfalda("camera", "fit", frame, "--intrinsics", "bad.xml", "--out", "c.yaml",
                   cwd=tmp_path, code=2)]
    for run in runs:
        assert "bad.xml: not a valid OpenCV FileStorage file (line 2: Invalid input)" in run.err
        assert len(run.err.strip().splitlines()) == 1, str(run)
    empty = tfalda("camera", "show", "empty.xml", cwd=tmp_path, code=2)
    assert "empty.xml: not a camera file" in empty.err
    assert not (tmp_path / "c.yaml").exists()
