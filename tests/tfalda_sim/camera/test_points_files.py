"""``camera fit --points`` / ``--bonnet FILE``: a bad pixel (NaN, infinite, text, huge) is
named by its file, its place and its value."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.cli_helpers import tfalda

FRAME = Path(__file__).parents[3] / "docs" / "cameras" / "reference-car-fit.png"
GOOD = [[100, 400], [200, 300], [300, 200]]


@pytest.mark.parametrize("bad,shown", [
    ("NaN", "is NaN"), ("Infinity", "is Infinity"), ("-Infinity", "is -Infinity"),
    ("1e999", "is Infinity"), ('"12"', 'must be a number of pixels, got "12"'),
    ("true", "must be a number of pixels, got true"), ("1" + "0" * 400, "is 1000"),
])
def test_a_bad_pixel_is_named_with_its_position(tmp_path: Path, bad: str, shown: str) -> None:
    centre = json.dumps(GOOD).replace("300]", f"{bad}]", 1)  # centre[1] v
    (tmp_path / "points.json").write_text(f'{{"centre": {centre}, "right": {json.dumps(GOOD)}}}')
    run = tfalda("camera", "fit", FRAME, "--intrinsics", "reference-car", "--points",
                 "points.json", "--out", "c.yaml", cwd=tmp_path, code=2)
    assert "--points points.json: centre[1] v " in run.err and shown in run.err, str(run)
    (tmp_path / "bonnet.json").write_text(json.dumps(GOOD).replace("300,", f"{bad},", 1))
    run = tfalda("camera", "fit", FRAME, "--intrinsics", "reference-car", "--bonnet",
                 "bonnet.json", "--out", "c.yaml", cwd=tmp_path, code=2)
    assert "--bonnet bonnet.json: polygon[2] u " in run.err and shown in run.err, str(run)
    assert not (tmp_path / "c.yaml").exists()


def test_a_pair_that_is_not_a_pair_is_named(tmp_path: Path) -> None:
    (tmp_path / "points.json").write_text('{"centre": [[1, 2], [3, 4, 5]]}')
    run = tfalda("camera", "fit", FRAME, "--intrinsics", "reference-car", "--points",
                 "points.json", "--out", "c.yaml", cwd=tmp_path, code=2)
    assert "centre[1] must be a [u, v] pixel pair, got [3, 4, 5]" in run.err, str(run)
