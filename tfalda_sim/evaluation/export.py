"""The thesis' test driver, export and import part (section 4.1.5): the lanes of every
frame as XML in listing 4.1's schema, and everything a run measured as JSON Lines.

XML (listing 4.1; ``lanes.xsd`` next to this module is its schema)::

    <root>
      <image seq="11" time="220">          time: the frame's time [ms] since the run began
        <line>                             one per ROI, the detector's order
          <point>142,425</point>           the lane's bottom end x,y [px]
          <point>238,340</point>           its top end x,y [px]
          <direction>-96</direction>       D = x_bottom − x_top [px]
          <lambda>-668</lambda>            λ of the distance function (NaN: first frame)
        </line>
      </image>
    </root>

The thesis' logger wrote integers; ours writes integers where the value is one and the
shortest exact decimal otherwise, so a file reads back to the same numbers.
"""

from __future__ import annotations

import json
import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tfalda_sim.fileio import atomic_write

from .runner import RunResult

XSD_PATH = Path(__file__).with_name("lanes.xsd")
"""XML Schema of listing 4.1's structure (validate with any XSD validator)."""


@dataclass(frozen=True)
class XmlImage:
    """One ``<image>`` read back: sequence number, time [ms], lanes ``(n, 4)``
    (x_top, y_top, x_bottom, y_bottom) [px], D ``(n,)`` [px] and λ ``(n,)``."""

    seq: int
    time_ms: int
    lanes: np.ndarray
    direction: np.ndarray
    lam: np.ndarray


def _num(v: float) -> str:
    v = float(v)
    if math.isnan(v):
        return "NaN"
    if math.isinf(v):
        return "INF" if v > 0 else "-INF"
    return str(int(v)) if v.is_integer() else repr(v)


def lanes_xml(run: RunResult) -> ET.Element:
    """The run's lanes as listing 4.1's element tree."""
    root = ET.Element("root")
    for k, seq in enumerate(run.seq):
        image = ET.SubElement(root, "image", seq=str(int(seq)),
                              time=str(int(round(run.time_s[k] * 1000))))
        for (xt, yt, xb, yb), d, lam in zip(run.lanes[k], run.d[k], run.lam[k], strict=True):
            line = ET.SubElement(image, "line")
            ET.SubElement(line, "point").text = f"{_num(xb)},{_num(yb)}"
            ET.SubElement(line, "point").text = f"{_num(xt)},{_num(yt)}"
            ET.SubElement(line, "direction").text = _num(d)
            ET.SubElement(line, "lambda").text = _num(lam)
    return root


def write_lanes_xml(run: RunResult, path: str | os.PathLike[str]) -> None:
    """Write the run's lanes as XML (listing 4.1), ISO-8859-1 as the thesis' logger."""
    tree = ET.ElementTree(lanes_xml(run))
    ET.indent(tree)
    with atomic_write(path, "wb") as f:
        tree.write(f, encoding="iso-8859-1", xml_declaration=True)


class LanesXmlError(ValueError):
    """A lanes XML file does not follow listing 4.1's structure."""


def _float(text: str | None, where: str) -> float:
    try:
        return float(text or "")
    except ValueError:
        raise LanesXmlError(f"{where}: {text!r} is not a number") from None


def read_lanes_xml(path: str | os.PathLike[str]) -> list[XmlImage]:
    """Read a lanes XML file back, checking listing 4.1's structure on the way; errors
    name the element at fault."""
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as e:
        raise LanesXmlError(f"cannot read {path}: {e}") from e
    if root.tag != "root":
        raise LanesXmlError(f"{path}: the document element must be <root>, got <{root.tag}>")
    images = []
    for i, image in enumerate(root):
        where = f"{path}: image {i}"
        if image.tag != "image":
            raise LanesXmlError(f"{where}: expected <image>, got <{image.tag}>")
        if set(image.attrib) != {"seq", "time"}:
            raise LanesXmlError(f"{where}: needs exactly the attributes seq and time, got "
                                f"{sorted(image.attrib)}")
        try:
            seq, time_ms = int(image.attrib["seq"]), int(image.attrib["time"])
        except ValueError:
            raise LanesXmlError(f"{where}: seq and time must be integers") from None
        lanes, dirs, lams = [], [], []
        for j, line in enumerate(image):
            lw = f"{where}, line {j}"
            if line.tag != "line" or [c.tag for c in line] != ["point", "point", "direction",
                                                              "lambda"]:
                raise LanesXmlError(f"{lw}: expected <line> with <point>, <point>, "
                                    "<direction>, <lambda> in this order")
            pts = []
            for c in line[:2]:
                parts = (c.text or "").split(",")
                if len(parts) != 2:
                    raise LanesXmlError(f"{lw}: a point must read 'x,y', got {c.text!r}")
                pts.append([_float(p, lw) for p in parts])
            (xb, yb), (xt, yt) = pts
            lanes.append([xt, yt, xb, yb])
            dirs.append(_float(line[2].text, lw))
            lams.append(_float(line[3].text, lw))
        images.append(XmlImage(seq, time_ms, np.array(lanes, np.float64).reshape(-1, 4),
                               np.array(dirs), np.array(lams)))
    return images


def _json_num(v: float) -> float | None:
    return None if not math.isfinite(v) else float(v)


def frame_records(run: RunResult) -> Iterable[dict[str, Any]]:
    """One JSON-ready dict per frame of the run (NaN written as null)."""
    conf = run.confidence
    for k, seq in enumerate(run.seq):
        yield {
            "scenario": run.scenario, "seed": run.seed, "run": run.label,
            "seq": int(seq), "time_s": float(run.time_s[k]),
            "confidence": float(conf[k]),
            "lanes": [[_json_num(v) for v in lane] for lane in run.lanes[k]],
            "rois": run.rois[k].astype(int).tolist(),
            "d": [_json_num(v) for v in run.d[k]], "lambda": [_json_num(v) for v in run.lam[k]],
            "hit_rates": [float(v) for v in run.hit_rates[k]],
            "accuracy": [_json_num(v) for v in run.accuracy[k]],
            "false_positive": run.false_positive[k].tolist(),
            "false_negative": run.false_negative[k].tolist(),
            "replaced": run.replaced[k].tolist(), "corrected": run.corrected[k].tolist(),
            "roi_reset": bool(run.roi_reset[k]), "fault_count": int(run.fault_count[k]),
            "state": run.state[k],
        }


def write_jsonl(runs: Iterable[RunResult], path: str | os.PathLike[str]) -> int:
    """Write every frame of every run as one JSON object per line; returns the lines."""
    n = 0
    with atomic_write(path) as f:
        for run in runs:
            for rec in frame_records(run):
                f.write(json.dumps(rec, allow_nan=False) + "\n")
                n += 1
    return n


def read_jsonl(path: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """Read a JSON Lines file written by ``write_jsonl``; errors name the line."""
    out = []
    with open(path, encoding="utf-8") as f:
        for i, line in enumerate(f, 1):
            if not line.strip():
                continue
            try:
                out.append(json.loads(line))
            except json.JSONDecodeError as e:
                raise ValueError(f"{path}:{i}: not a JSON object: {e}") from e
    return out
