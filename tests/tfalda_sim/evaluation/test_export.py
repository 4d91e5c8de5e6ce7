"""XML (listing 4.1) and JSON Lines exports: schema, read-back, bad files; charts."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
import xmlschema

from tfalda_sim.evaluation import WITH_LIS, WITHOUT_LIS, RunResult, run_scenario
from tfalda_sim.evaluation.charts import plot_ablation, plot_confidence, plot_seeds
from tfalda_sim.evaluation.export import (
    XSD_PATH,
    LanesXmlError,
    read_jsonl,
    read_lanes_xml,
    write_jsonl,
    write_lanes_xml,
)
from tfalda_sim.evaluation.scenarios import Scenario
from tfalda_sim.evaluation.trajectory import Trajectory
from tfalda_sim.perception import DetectorConfig
from tfalda_sim.rendering import Renderer
from tfalda_sim.tracks import load_named

LISTING_4_1 = """<root>
<image seq ="11" time="1211011323" >
<line>
<point>142,425</point>
<point>238,340</point>
<direction>-96</direction>
<lambda>-668</lambda>
</line>
</image>
</root>
"""


@pytest.fixture(scope="module")
def runs() -> dict[str, RunResult]:
    track = load_named("thesis")
    sc = Scenario("short", track, Trajectory.along_lane(track, n_frames=12, speed_m_s=4.0,
                                                        s_start_m=7.0), first_seq=40)
    return run_scenario(sc, {WITH_LIS: DetectorConfig.thesis(),
                             WITHOUT_LIS: DetectorConfig.without_lis()}, renderer=Renderer())


def test_the_thesis_listing_validates_and_reads(tmp_path: Path) -> None:
    path = tmp_path / "listing.xml"
    path.write_text(LISTING_4_1)
    xmlschema.XMLSchema(XSD_PATH).validate(path)
    (image,) = read_lanes_xml(path)
    assert image.seq == 11 and image.time_ms == 1211011323
    # the first point is the lane's bottom end: D = x_bottom − x_top = 142 − 238
    assert image.lanes.tolist() == [[238.0, 340.0, 142.0, 425.0]]
    assert image.direction[0] == image.lanes[0, 2] - image.lanes[0, 0]
    assert image.lam.tolist() == [-668.0]


def test_run_xml_validates_and_reads_back(runs: dict[str, RunResult], tmp_path: Path) -> None:
    run = runs[WITH_LIS]
    path = tmp_path / "lanes.xml"
    write_lanes_xml(run, path)
    assert path.read_bytes().startswith(b"<?xml version='1.0' encoding='iso-8859-1'?>")
    xmlschema.XMLSchema(XSD_PATH).validate(path)
    images = read_lanes_xml(path)
    assert [im.seq for im in images] == run.seq.tolist() == list(range(40, 52))
    assert [im.time_ms for im in images] == [20 * k for k in range(12)]
    for k, im in enumerate(images):
        assert np.array_equal(im.lanes, run.lanes[k])
        assert np.array_equal(im.direction, run.d[k])
        assert np.array_equal(im.lam, run.lam[k], equal_nan=True)
    assert np.isnan(images[0].lam).all()  # the first frame has no λ


@pytest.mark.parametrize("text, message", [
    ("<lanes/>", "must be <root>"),
    ("<root><frame seq='1' time='0'/></root>", "expected <image>"),
    ("<root><image seq='1'/></root>", "attributes seq and time"),
    ("<root><image seq='x' time='0'/></root>", "integers"),
    ("<root><image seq='1' time='0'><line><point>1,2</point></line></image></root>",
     "in this order"),
    ("<root><image seq='1' time='0'><line><point>1;2</point><point>1,2</point>"
     "<direction>0</direction><lambda>0</lambda></line></image></root>", "'x,y'"),
    ("<root><image seq='1' time='0'><line><point>1,2</point><point>1,2</point>"
     "<direction>left</direction><lambda>0</lambda></line></image></root>", "not a number"),
    ("<root><image", "cannot read"),
])
def test_malformed_xml_is_named(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.xml"
    path.write_text(text)
    with pytest.raises(LanesXmlError, match=message):
        read_lanes_xml(path)


def test_jsonl_holds_every_frame_of_every_run(runs: dict[str, RunResult],
                                              tmp_path: Path) -> None:
    path = tmp_path / "runs.jsonl"
    assert write_jsonl(runs.values(), path) == 24
    recs = read_jsonl(path)
    assert [r["run"] for r in recs] == [WITH_LIS] * 12 + [WITHOUT_LIS] * 12
    run = runs[WITHOUT_LIS]
    for k, rec in enumerate(recs[12:]):
        assert rec["seq"] == 40 + k
        assert rec["confidence"] == pytest.approx(run.confidence[k])
        lanes = np.array([[math.nan if v is None else v for v in lane] for lane in rec["lanes"]])
        assert np.array_equal(lanes, run.lanes[k], equal_nan=True)
        assert rec["rois"] == run.rois[k].tolist()
    (tmp_path / "bad.jsonl").write_text('{"a": 1}\n{oops\n')
    with pytest.raises(ValueError, match=r"bad\.jsonl:2"):
        read_jsonl(tmp_path / "bad.jsonl")


def test_a_failed_write_keeps_the_existing_file(runs: dict[str, RunResult],
                                                tmp_path: Path) -> None:
    path = tmp_path / "lanes.xml"
    path.write_text("precious")

    class Boom(RunResult):
        @property
        def confidence(self) -> np.ndarray:
            raise RuntimeError("disk full")

    broken = Boom(**{f: getattr(runs[WITH_LIS], f) for f in runs[WITH_LIS].__dataclass_fields__})
    with pytest.raises(RuntimeError):
        write_jsonl([broken], path)
    assert path.read_text() == "precious"
    assert [p.name for p in tmp_path.iterdir()] == ["lanes.xml"]  # no temporary left


def _png(path: Path) -> np.ndarray:
    image = cv2.imread(str(path))
    assert image is not None and image.shape[0] > 200 and image.shape[1] > 400
    return image


def test_charts_are_written(runs: dict[str, RunResult], tmp_path: Path) -> None:
    plot_confidence(runs, tmp_path / "c.png", title="test")
    image = _png(tmp_path / "c.png")
    # the thesis' colours: a red and a blue line are drawn
    b, g, r = (image[..., i].astype(int) for i in range(3))
    assert ((r > 150) & (g < 80) & (b < 80)).sum() > 50
    assert ((b > 120) & (r < 80)).sum() > 50
    summaries = [dict(run.summary(), seed=s) for s in (3, 4) for run in runs.values()]
    plot_seeds(summaries, tmp_path / "s.png", title="seeds")
    _png(tmp_path / "s.png")
    rows = [{"config": label, **run.summary()} for label, run in runs.items()]
    plot_ablation(rows, tmp_path / "a.png", title="ablation")
    _png(tmp_path / "a.png")
