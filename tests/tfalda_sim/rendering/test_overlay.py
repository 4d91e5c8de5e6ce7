"""Drawing the Hough baseline: its segments and the seed's 2×2 stage view."""

from __future__ import annotations

import cv2
import numpy as np

from tfalda_sim.perception.hough import CROP_HEIGHT_PX, HoughConfig, HoughDetector
from tfalda_sim.rendering.overlay import draw_hough, stage_view

W_PX = 752


def frame_with(*lines: tuple[int, int, int, int], thickness: int = 14) -> np.ndarray:
    """A dark 480×752 frame with white lines (x0, y0, x1, y1)."""
    frame = np.full((480, W_PX), 40, np.uint8)
    for x0, y0, x1, y1 in lines:
        cv2.line(frame, (x0, y0), (x1, y1), 255, thickness)
    return frame


def test_stage_view_is_the_2x2_figure() -> None:
    lines = ((100, 477, 300, 219), (650, 477, 430, 219))
    r = HoughDetector(HoughConfig(car_mask=())).detect(frame_with(*lines))
    view = stage_view(r)
    assert view.shape == (518, 1504, 3) and view.dtype == np.uint8
    ch, cw = CROP_HEIGHT_PX, W_PX
    below_title = slice(30, ch)
    # panels 1–3 are the stage images (white on black) below their titles
    for panel, image in (((0, 0), r.binary), ((0, 1), r.sobel), ((1, 0), r.merged)):
        top, left = panel[0] * ch, panel[1] * cw
        got = view[top:top + ch, left:left + cw]
        assert np.array_equal(got[below_title, :, 1], image[below_title].astype(np.uint8) * 255)
    red = (view[..., 2] > 200) & (view[..., 1] < 60) & (view[..., 0] < 60)
    assert red[ch:, cw:].sum() > 200  # the segments, in panel 4 only
    assert not red[:ch].any() and not red[ch:, :cw].any()




def test_a_black_frame_draws_an_empty_view() -> None:
    r = HoughDetector().detect(np.zeros((480, W_PX), np.uint8))
    assert stage_view(r).shape == (2 * CROP_HEIGHT_PX, 2 * W_PX, 3)


def test_draw_hough_puts_the_segments_where_they_were_found() -> None:
    frame = frame_with((100, 477, 300, 219))
    r = HoughDetector(HoughConfig(car_mask=())).detect(frame)
    out = draw_hough(frame, r, text="t")
    assert out.shape == (480, W_PX, 3) and frame.ndim == 2  # the input is left as it was
    red = (out[..., 2] > 200) & (out[..., 1] < 60) & (out[..., 0] < 60)
    ys, xs = np.nonzero(red[30:])
    assert len(xs) > 100
    # the red pixels lie on the drawn line (within its width)
    x_line = 100 + (477 - (ys + 30)) * (200 / 258)
    assert np.abs(xs - x_line).max() < 14
