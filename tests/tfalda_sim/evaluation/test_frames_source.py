"""``evaluate --frames RECORDING --topic … --labels DIR``: the labelled frames of a ROS bag
or MCAP file scored with the black-box metric — the same figures as the same frames in a
folder; the detectors see the unlabelled frames between; bad labels and sizes refused."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.cli_helpers import tfalda
from tests.tfalda_sim.sources.recordings import write_mcap, write_ros2_bag

REFERENCE = Path(__file__).resolve().parents[2] / "data" / "reference"
T0_NS = 1_700_000_000_000_000_000


def frame(name: str) -> np.ndarray:
    return cv2.imread(str(REFERENCE / f"{name}.png"), cv2.IMREAD_GRAYSCALE)


def labels_for(folder: Path, index: int, name: str = "straight-road") -> Path:
    """The reference labels of ``name`` as the labels of a recording's frame ``index``."""
    folder.mkdir(exist_ok=True)
    doc = json.loads((REFERENCE / f"{name}.labels.json").read_text())
    doc["frame"] = f"frame-{index}"
    path = folder / f"frame-{index}.labels.json"
    path.write_text(json.dumps(doc))
    return path


def test_a_recordings_labelled_frame_scores_as_the_same_frame_in_a_folder(
        tmp_path: Path) -> None:
    frames = [frame("start-road"), frame("straight-road"), frame("straight-road")]
    bag = write_ros2_bag(tmp_path / "run", frames, [T0_NS + k * 20_000_000 for k in range(3)],
                         storage="mcap", topic="/cam/image_raw",
                         extra_topics=["/cam/other"])
    labels_for(tmp_path / "labels", 2)
    rec = tfalda("evaluate", "--frames", bag, "--topic", "/cam/image_raw", "--labels",
                 "labels", "--camera", "reference-car", "--stills", "--repeat", "20",
                 "--detector", "both", "--json", cwd=tmp_path).json()
    folder = tmp_path / "folder"
    folder.mkdir()
    shutil.copy(REFERENCE / "straight-road.png", folder)
    shutil.copy(REFERENCE / "straight-road.labels.json", folder)
    ref = tfalda("evaluate", "--frames", folder, "--labels", folder, "--camera",
                 "reference-car", "--stills", "--repeat", "20", "--detector", "both",
                 "--json", cwd=tmp_path).json()
    for label, det in rec["detectors"].items():
        assert det["frames"] == 1 and det["per_frame"][0]["frame"] == "frame-2"
        want = ref["detectors"][label]["per_frame"][0]
        got = det["per_frame"][0]
        assert got["hit_rates"] == want["hit_rates"] and got["ego_found"] == want["ego_found"]
    assert rec["detectors"]["with LIS"]["per_frame"][0]["lanes_on_markings"] >= 3
    # a sequence: TFALDA sees frames 0 and 1 before the labelled one (the LIS tracks them)
    seq = tfalda("evaluate", "--frames", bag, "--topic", "/cam/image_raw", "--labels",
                 "labels", "--camera", "reference-car", "--json", cwd=tmp_path).json()
    assert seq["detectors"]["with LIS"]["frames"] == 1


@pytest.mark.parametrize("change, says", [
    ({"frame": "frame-1"}, "labels the frame 'frame-1', not 'frame-2'"),
    ({"image_width_px": 640}, "labels are for 640×480 frames"),
])
def test_labels_of_another_frame_or_size_are_refused(change: dict, says: str,
                                                      tmp_path: Path) -> None:
    frames = [frame("straight-road")] * 3
    mcap = write_mcap(tmp_path / "run.mcap", frames, [T0_NS + k * 20_000_000 for k in range(3)])
    path = labels_for(tmp_path / "labels", 2)
    path.write_text(json.dumps(json.loads(path.read_text()) | change))
    run = tfalda("evaluate", "--frames", mcap, "--labels", "labels", "--camera",
                 "reference-car", cwd=tmp_path, code=2)
    assert says in run.err


def test_recording_inputs_that_cannot_be_scored(tmp_path: Path) -> None:
    small = [cv2.resize(frame("straight-road"), (376, 240))] * 2
    mcap = write_mcap(tmp_path / "run.mcap", small, [T0_NS, T0_NS + 20_000_000])
    labels_for(tmp_path / "labels", 1)
    run = tfalda("evaluate", "--frames", mcap, "--labels", "labels", "--camera",
                 "reference-car", cwd=tmp_path, code=2)
    assert "376×240 px, the camera's are 752×480" in run.err
    labels_for(tmp_path / "far", 9)
    full = write_mcap(tmp_path / "full.mcap", [frame("straight-road")] * 2,
                      [T0_NS, T0_NS + 20_000_000])
    run = tfalda("evaluate", "--frames", full, "--labels", "far", "--camera", "reference-car",
                 cwd=tmp_path, code=2)
    assert "labels name frame 9" in run.err
    (tmp_path / "none").mkdir()
    run = tfalda("evaluate", "--frames", full, "--labels", "none", cwd=tmp_path, code=2)
    assert "no frame-<i>.labels.json files" in run.err
    run = tfalda("evaluate", "--frames", full, "--topic", "/nope", "--labels", "far",
                 cwd=tmp_path, code=2)
    assert "/nope" in run.err
    folder = tmp_path / "folder"
    folder.mkdir()
    run = tfalda("evaluate", "--frames", folder, "--topic", "/x", "--labels", "far",
                 cwd=tmp_path, code=2)
    assert "drop --topic" in run.err
