"""TFALDA's pre-processing and automatic lane detection on one ROI.

Pre-processing (section 3.2.1, listing A.2): crop → ``cvResize`` by the resample factor
→ 3×3 Sobel, the kernel chosen by the Sobel manager from the last lane's angle.

Automatic lane detection (listing A.2, ``getCV``/``Ci``/``I``): every x on the top row of
the resampled gradient image is a start point; for each, every x on the bottom row is tried
as end point and the gradient values along the straight segment between them are summed.
The best end point gives the start's candidate: ``P`` = start x, ``D`` = end x − start x,
``I`` = that largest sum. Ends are tried left to right and only a strictly larger sum
replaces the best so far, so the leftmost of equal sums wins; a start whose every sum is 0
keeps the listing's initial end x = 0.

Speed: the pixels of a segment depend only on ``D`` (and the image height), not on the
start, so for one ``D`` the sums of all starts are a few shifted row additions, which
vectorise; that is ``W² · H`` additions in SIMD instead of ``W²`` scalar line walks. The
starts are summed in blocks of ``SIMD_BLOCK`` lanes held in vector registers over all the
segment's samples (``_block_sums``), reading the samples' offsets from a table built once
per image height (``segment_steps``): a row addition through memory per sample, with its
stepped offset, had cost 2–4× as much. The detector's images hold their sums in 16 bits
when no segment can exceed them (at most ``UINT16_MAX_SAMPLES`` samples of 255).
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from ..kernels import LITTLE_ENDIAN, load_pair
from .params import EdgeMode, TfaldaConfig


def line_offset(i: int, dx: int, n: int) -> int:
    """Offset of the ``i``-th of ``n`` samples on a segment spanning ``dx`` [px]:
    ``round(i · dx / (n − 1))``, halves rounded away from zero (plain Python, for reference
    implementations; the kernel inlines the same integer formula)."""
    if n <= 1:
        return 0
    mag = (2 * i * abs(dx) + (n - 1)) // (2 * (n - 1))
    return mag if dx >= 0 else -mag


def integer_dda_pixels(x0: int, x1: int, height: int) -> list[tuple[int, int]]:
    """The pixels ``(x, y)`` of the segment from ``(x0, 0)`` to ``(x1, height − 1)``: an
    integer DDA, one sample per step of its longer axis, ends included, offsets
    ``line_offset`` (halves rounded away from zero) — the samples of a candidate segment,
    Bresenham's pixels up to ties (``evaluation.metrics.dda_pixels`` rounds ties to even)."""
    dx, dy = x1 - x0, height - 1
    n = max(abs(dx), dy) + 1
    return [(x0 + line_offset(i, dx, n), line_offset(i, dy, n)) for i in range(n)]


UINT16_MAX_SAMPLES: int = 65535 // 255
"""Largest ``max(height, width)`` of a gradient image whose segment sums fit uint16 (a
segment has at most that many samples of at most 255) [px]."""

SIMD_BLOCK: int = 32
"""Starts summed at once by the candidate search, in vector registers [lanes]: 32 uint16
sums fill one 512-bit register (two of AVX2), 32 int32 sums two (four of AVX2). Row ends
are padded to whole blocks (the extra lanes read on into the next row, the last rows into
the zeros past the image; they are never used)."""

SEGMENT_TABLES_KEPT: int = 16
"""Segment tables ``segment_steps`` keeps (one per image height and width class; the
thesis' ROIs use 2–4): bounds their number, whatever the images asked for (a table
holds ≈ width²/2 samples of 8 bytes: 33 MB for a 2000 px wide image)."""


def _make_block_sums(blocks: int):  # type: ignore[no-untyped-def]  # numba's intrinsic
    """An intrinsic ``(flat, steps, first, n, width, sign, base, out, at)``: for
    ``blocks`` blocks of ``SIMD_BLOCK`` starts from ``base``, the sums over ``n`` samples
    of one segment of the pixels at ``flat[base + block·SIMD_BLOCK + y·width + sign·x +
    lane]``, ``(y, x)`` the samples' rows and column offsets ``steps[first:first + n]``,
    written to ``out[at + block·SIMD_BLOCK + lane]``. The sums stay in vector registers
    over all samples (numba's loops kept them in memory: a load, add and store per lane
    and sample). No bounds checks: ``search_candidates`` checks its arrays before. (An
    offset, not a slice ``out[at:]``: a slice takes and drops a reference to ``out``, two
    atomic operations per call, and the search makes ≈ 2 × width calls per ROI.)"""

    @intrinsic
    def block_sums(typingctx, flat, steps, first, n, width, sign, base, out, at
                   ):  # type: ignore[no-untyped-def]
        # Contiguous arrays of the shapes search_candidates checks, a writable out: the
        # loads and stores step through raw memory.
        if not (isinstance(flat, types.Array) and isinstance(out, types.Array)
                and flat.dtype == out.dtype and flat.dtype in (types.uint16, types.int32)
                and isinstance(steps, types.Array) and steps.dtype == types.int32
                and flat.layout == out.layout == steps.layout == "C"
                and flat.ndim == out.ndim == 1 and steps.ndim == 2 and out.mutable):
            return None
        ip = types.intp

        def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
            data = context.make_array(signature.args[0])(context, builder, args[0]).data
            table = context.make_array(signature.args[1])(context, builder, args[1]).data
            dest = context.make_array(signature.args[7])(context, builder, args[7]).data
            first_, n_, width_, sign_, base_ = args[2:7]
            out_at = args[8]
            vector = ir.VectorType(context.get_data_type(signature.args[0].dtype), SIMD_BLOCK)
            align = signature.args[0].dtype.bitwidth // 8
            intp = base_.type
            accs = [cgutils.alloca_once_value(builder, ir.Constant(vector, None))
                    for _ in range(blocks)]
            with cgutils.for_range(builder, n_) as loop:
                k = builder.mul(builder.add(first_, loop.index), ir.Constant(intp, 2))
                y = builder.sext(builder.load(builder.gep(table, [k])), intp)
                x = builder.sext(builder.load(builder.gep(
                    table, [builder.add(k, ir.Constant(intp, 1))])), intp)
                at = builder.add(base_, builder.add(builder.mul(y, width_),
                                                    builder.mul(sign_, x)))
                for b, acc in enumerate(accs):
                    ptr = builder.gep(data, [builder.add(at, ir.Constant(intp, b * SIMD_BLOCK))])
                    value = builder.load(builder.bitcast(ptr, vector.as_pointer()), align=align)
                    builder.store(builder.add(builder.load(acc), value), acc)
            for b, acc in enumerate(accs):
                ptr = builder.gep(dest, [builder.add(out_at,
                                                     ir.Constant(intp, b * SIMD_BLOCK))])
                builder.store(builder.load(acc), builder.bitcast(ptr, vector.as_pointer()),
                              align=align)
            return context.get_dummy_value()

        return types.void(flat, steps, ip, ip, ip, ip, ip, out, ip), codegen

    return block_sums


_block_sums_1 = _make_block_sums(1)
_block_sums_2 = _make_block_sums(2)
_block_sums_3 = _make_block_sums(3)


@njit(cache=True, error_model="numpy")
def _build_segment_steps(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """The samples of every segment of an image ``height`` rows high, for every
    ``|D|`` < ``width``: ``(steps, first)``, ``steps`` int32 ``(total, 2)`` rows of
    (row, column offset ≥ 0), the segment of ``|D|`` = d at ``steps[first[d]:first[d + 1]]``
    (``first`` int64, ``width + 1`` entries). Sample i sits at
    ``round(i·|D|/(n−1)), round(i·(height − 1)/(n−1))`` (halves away from zero), stepped with
    remainders instead of two integer divisions per sample; a negative ``D`` mirrors the
    column offsets."""
    dy = height - 1
    first = np.empty(width + 1, np.int64)
    total = 0
    for adx in range(width):
        first[adx] = total
        total += max(adx, dy) + 1
    first[width] = total
    steps = np.empty((total, 2), np.int32)
    for adx in range(width):
        n = max(adx, dy) + 1
        den = 2 * (n - 1)
        ox = 0
        y = 0
        rx = n - 1
        ry = n - 1
        at = first[adx]
        for i in range(n):
            if i > 0:
                rx += 2 * adx
                if rx >= den:
                    rx -= den
                    ox += 1
                ry += 2 * dy
                if ry >= den:
                    ry -= den
                    y += 1
            steps[at + i, 0] = y
            steps[at + i, 1] = ox
    return steps, first


def segment_steps(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """``_build_segment_steps`` for images ``height`` × ``width`` [px], read-only and kept
    (``SEGMENT_TABLES_KEPT``): a table serves every width up to its own, which is rounded
    up to a power of two (at least 128), so a detector's ROIs of changing widths share one
    table per height."""
    if height < 1 or width < 1:
        raise ValueError(f"a gradient image of {height} × {width} px: both must be ≥ 1")
    return _segment_steps(int(height), max(128, 1 << (int(width) - 1).bit_length()))


@functools.lru_cache(maxsize=SEGMENT_TABLES_KEPT)
def _segment_steps(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    steps, first = _build_segment_steps(height, width)
    steps.flags.writeable = False
    first.flags.writeable = False
    return steps, first


@njit(cache=True, error_model="numpy")
def search_candidates(flat: np.ndarray, height: int, width: int,
                      segments: tuple[np.ndarray, np.ndarray], best_i: np.ndarray,
                      best_end: np.ndarray, sums: np.ndarray) -> None:
    """For every start x of the top row of an image (``flat``: its ``height`` × ``width``
    pixels row by row, int32 — or uint16 if no segment sum can exceed 16 bits
    (``UINT16_MAX_SAMPLES``) — followed by at least ``SIMD_BLOCK`` padding values): the
    largest segment sum over all end x of the bottom row (``best_i``, int32) and that end x
    (``best_end``, int32). ``segments`` is ``segment_steps(height, width)`` (read-only;
    its height and size are checked, not every entry); ``sums`` is
    scratch of ``flat``'s type, of length ≥ width + ``SIMD_BLOCK``. Arrays too short for
    these raise ValueError; strided, multi-dimensional or read-only ones fail to compile
    (numba's TypingError): the block sums read and write contiguous memory without bounds
    checks."""
    steps, first = segments
    w = width
    if height < 1 or w < 1:
        raise ValueError("search_candidates: height and width must be ≥ 1")
    if flat.shape[0] < height * w + SIMD_BLOCK or sums.shape[0] < w + SIMD_BLOCK \
            or best_i.shape[0] < w or best_end.shape[0] < w:
        raise ValueError("search_candidates: flat needs height·width + SIMD_BLOCK values, "
                         "sums width + SIMD_BLOCK, best_i and best_end width")
    if first.shape[0] < w + 1 or first[1] - first[0] != height \
            or steps.shape[0] < first[w] or steps.shape[1] != 2:
        raise ValueError("search_candidates: segments are not segment_steps(height, width)")
    block = SIMD_BLOCK
    for x in range(w):
        best_i[x] = 0
        best_end[x] = 0
    dy = height - 1
    for dx in range(-(w - 1), w):  # ascending end x for every start
        adx = abs(dx)
        n = max(adx, dy) + 1
        lo = max(0, -dx)
        m = min(w, w - dx) - lo
        sign = 1 if dx >= 0 else -1
        at = first[adx]
        done = 0
        left = (m + block - 1) // block
        while left > 0:  # up to 3 blocks (96 starts) at once: the thesis' ROIs in one go
            if left >= 3:
                _block_sums_3(flat, steps, at, n, w, sign, lo + done, sums, done)
                done += 3 * block
                left -= 3
            elif left == 2:
                _block_sums_2(flat, steps, at, n, w, sign, lo + done, sums, done)
                left = 0
            else:
                _block_sums_1(flat, steps, at, n, w, sign, lo + done, sums, done)
                left = 0
        for k in range(m):  # branch-free update: vectorises
            x = lo + k
            gt = np.int32(sums[k] > best_i[x])
            best_i[x] = best_i[x] + gt * (sums[k] - best_i[x])
            best_end[x] = best_end[x] + gt * (x + dx - best_end[x])


def sobel_horizontal_edges(lane_d_px: float, lane_height_px: float,
                           switch_angle_deg: float) -> bool:
    """The Sobel manager (section 3.1.1): True — use the kernel that enhances horizontal
    edges (∂/∂y) — when the last lane leans more than ``switch_angle_deg`` from the
    vertical, else the default kernel for vertical edges (∂/∂x)."""
    angle = math.degrees(math.atan2(abs(lane_d_px), max(lane_height_px, 1e-9)))
    return angle > switch_angle_deg


def resample_shape(height: int, width: int, config: TfaldaConfig) -> tuple[int, int]:
    """``(height, width)`` [px] of a ``height`` × ``width`` crop resampled by the
    resample factor (at least 2 × 1 px; the crop's own with a factor of 1)."""
    f = config.resample_factor
    if f == 1.0:
        return height, width
    return max(2, int(height / f)), max(1, int(width / f))


def resample(crop: np.ndarray, config: TfaldaConfig) -> np.ndarray:
    """One ROI crop resized by the resample factor (``cvResize``, bilinear; at least
    2×1 px): OpenCV's, the reference of ``resample_into`` (the detector's path)."""
    h, w = resample_shape(*crop.shape, config)
    if (h, w) == crop.shape:
        return crop
    return cv2.resize(crop, (w, h), interpolation=cv2.INTER_LINEAR)


RESIZE_COEF_BITS: int = 11
"""Fixed-point bits of OpenCV's bilinear resize weights for 8-bit images
(``INTER_RESIZE_COEF_BITS``): a weight is ``round(w · 2¹¹)``."""


@njit(cache=True, error_model="numpy")
def _resize_taps(dst: int, src: int, clamp: bool
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """OpenCV's bilinear taps along one axis of ``src`` → ``dst`` px: per output pixel the
    first source pixel and the two fixed-point weights (``cv::resize``: the pixel centre's
    source coordinate in float32, its floor, the weights rounded half to even). Along x
    (``clamp``) a coordinate left of 0 or past the last pixel takes that pixel alone, and
    outputs from the returned index on read one pixel (the second tap would lie outside);
    along y the coordinate stays and the rows are clamped when read."""
    scale = 1.0 / (np.float64(dst) / np.float64(src))  # as cv::resize computes it
    one = np.float32(1 << RESIZE_COEF_BITS)
    first = np.empty(dst, np.int32)
    w0 = np.empty(dst, np.int32)
    w1 = np.empty(dst, np.int32)
    limit = dst
    for d in range(dst):
        f = np.float32((d + 0.5) * scale - 0.5)
        s = int(np.floor(f))
        f = np.float32(f - np.float32(s))
        if clamp:
            if s < 0:
                f, s = np.float32(0.0), 0
            if s + 1 >= src:
                limit = min(limit, d)
                if s >= src - 1:
                    f, s = np.float32(0.0), src - 1
        first[d] = s
        w0[d] = np.int32(np.rint(np.float32(np.float32(1.0) - f) * one))
        w1[d] = np.int32(np.rint(f * one))
    return first, w0, w1, limit


@njit(cache=True, error_model="numpy")
def resample_into(crop: np.ndarray, out: np.ndarray) -> None:
    """``out`` (uint8, h × w) = ``cv2.resize(crop, (w, h), interpolation=INTER_LINEAR)`` of
    the uint8 ``crop``, bit for bit (tested against the installed OpenCV, 5.1): fixed-point
    weights of ``RESIZE_COEF_BITS``, exact integer row sums, and the rounding of OpenCV's
    vectorised vertical pass, ``((r0 >> 4)·b0 >> 16) + ((r1 >> 4)·b1 >> 16)`` then
    ``(v + 2) >> 2``, which OpenCV's results follow in every column, tails included (its
    scalar formula, ``(r0·b0 + r1·b1 + 2²¹) >> 22``, differs in ~5 % of pixels). A crop
    of ``out``'s size is copied. Every sum fits int32 (≤ 255 · 2¹¹ · 2). The two taps of
    a row are one 16-bit load where the crop's columns are adjacent in memory: ≈ 1.2–1.45×
    OpenCV's speed here, without its ≈ 7–15 µs per call."""
    sh, sw = crop.shape
    dh, dw = out.shape
    if sh < 1 or sw < 1 or dh < 1 or dw < 1:
        raise ValueError("resample_into: crop and out must be at least 1 × 1 px")
    if sh == dh and sw == dw:
        # Element by element: an array assigned to a slice makes numba compile its
        # shape-mismatch message (≈ 5 s of a cold start), for shapes equal here.
        for r in range(sh):
            for c in range(sw):
                out[r, c] = crop[r, c]
        return
    x_first, a0, a1, x_limit = _resize_taps(dw, sw, True)
    y_first, b0s, b1s, _ = _resize_taps(dh, sh, False)
    one = np.int32(1 << RESIZE_COEF_BITS)
    adjacent = crop.strides[1] == 1
    low = 0 if LITTLE_ENDIAN else 8  # where the left tap's byte sits in a pair
    top = np.empty(dw, np.int32)  # the horizontal pass of the two source rows
    bottom = np.empty(dw, np.int32)
    for y in range(dh):
        for k in range(2):  # a downscale reads each source row about once: no row cache
            src = crop[min(max(y_first[y] + k, 0), sh - 1)]
            dst = top if k == 0 else bottom
            if adjacent:
                for x in range(x_limit):
                    pair = np.int32(load_pair(src, x_first[x]))
                    dst[x] = ((pair >> low) & 255) * a0[x] + ((pair >> (8 - low)) & 255) * a1[x]
            else:
                for x in range(x_limit):
                    s = x_first[x]
                    dst[x] = np.int32(src[s]) * a0[x] + np.int32(src[s + 1]) * a1[x]
            for x in range(x_limit, dw):
                dst[x] = np.int32(src[x_first[x]]) * one
        b0, b1 = b0s[y], b1s[y]
        o = out[y]
        for x in range(dw):
            v = (((top[x] >> 4) * b0) >> 16) + (((bottom[x] >> 4) * b1) >> 16)
            o[x] = np.uint8(min(max((v + 2) >> 2, 0), 255))


def preprocess(crop: np.ndarray, config: TfaldaConfig, horizontal_edges: bool) -> np.ndarray:
    """Resampled 8-bit gradient image of one ROI crop (uint8, at least 2×1 px): OpenCV's
    Sobel, the reference of ``sobel_into`` (the detector's path)."""
    small = resample(crop, config)
    dx, dy = (0, 1) if horizontal_edges else (1, 0)
    if config.edge_mode is EdgeMode.RISING:
        return cv2.Sobel(small, cv2.CV_8U, dx, dy, ksize=3)  # negatives clip to 0
    return cv2.convertScaleAbs(cv2.Sobel(small, cv2.CV_16S, dx, dy, ksize=3))


def distance_lambda(p_px: np.ndarray, d_px: np.ndarray, i: np.ndarray, previous_p_px: float,
                    previous_d_px: float, previous_i: float, kp: float, kd: float,
                    ki: float) -> np.ndarray:
    """The thesis' distance function λ (listing 3.1) of every candidate against the lane
    the ROI held last frame: ``kp·|P − P'| + kd·|D − D'| + ki·(I' − I)``, with ``P``, ``D``
    in image pixels and ``I`` the summed gradient; the candidate of smallest λ is the lane
    (a weaker gradient than last frame's costs, a stronger one pays)."""
    return kp * np.abs(p_px - previous_p_px) + kd * np.abs(d_px - previous_d_px) \
        + ki * (previous_i - i)


def candidates(gradient: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(P, D, I)`` of every start x of a gradient image, in its own pixels (int64)."""
    h, w = gradient.shape
    best_i = np.empty(w, np.int32)
    best_end = np.empty(w, np.int32)
    flat = np.zeros(h * w + SIMD_BLOCK, np.int32)  # the padding the blocks read past the end
    flat[:h * w] = gradient.ravel()
    search_candidates(flat, h, w, segment_steps(h, w), best_i, best_end,
                      np.empty(w + SIMD_BLOCK, np.int32))
    p = np.arange(w, dtype=np.int64)
    return p, best_end.astype(np.int64) - p, best_i.astype(np.int64)


@njit(cache=True, error_model="numpy")
def _reflect_101(i: int, n: int) -> int:
    """OpenCV's ``BORDER_REFLECT_101`` index (Sobel's default border): −1 → 1, n → n − 2;
    a single pixel is its own neighbour."""
    if n == 1:
        return 0
    if i < 0:
        return -i
    if i >= n:
        return 2 * n - 2 - i
    return i


@njit(cache=True, error_model="numpy")
def sobel_into(small: np.ndarray, horizontal_edges: bool, rising: bool, flat: np.ndarray
               ) -> None:
    """``preprocess``'s 3×3 Sobel of the resampled crop ``small`` (uint8), row by row into
    the int32 ``flat``: ∂/∂x (kernel [−1 0 1] × [1 2 1]ᵀ), or ∂/∂y if
    ``horizontal_edges``, borders reflected (101) as OpenCV's; ``rising`` clips negatives
    to 0 (an 8-bit Sobel), else |gradient|; both saturate at 255. Integer arithmetic, so
    it equals ``cv2.Sobel`` exactly (tested), without OpenCV's ≈ 10 µs per call."""
    h, w = small.shape
    for r in range(h):
        top = small[_reflect_101(r - 1, h)]
        mid = small[r]
        bottom = small[_reflect_101(r + 1, h)]
        out = flat[r * w:(r + 1) * w]
        for c in range(1, w - 1):  # inside: a loop that vectorises
            out[c] = _sobel_at(top, mid, bottom, c - 1, c, c + 1, horizontal_edges, rising)
        for c in range(0, w, max(w - 1, 1)):  # the first and last columns, reflected
            out[c] = _sobel_at(top, mid, bottom, _reflect_101(c - 1, w), c,
                               _reflect_101(c + 1, w), horizontal_edges, rising)


@njit(cache=True, error_model="numpy", inline="always")
def _sobel_at(top: np.ndarray, mid: np.ndarray, bottom: np.ndarray, c0: int, c: int, c2: int,
              horizontal_edges: bool, rising: bool) -> np.int32:
    """``sobel_into`` at column ``c`` of the rows ``top``, ``mid``, ``bottom``, with the
    neighbour columns ``c0`` and ``c2``."""
    if horizontal_edges:  # ∂/∂y: [1 2 1] along the row, [−1 0 1] down
        v = (np.int32(bottom[c0]) + 2 * np.int32(bottom[c]) + np.int32(bottom[c2])) \
            - (np.int32(top[c0]) + 2 * np.int32(top[c]) + np.int32(top[c2]))
    else:  # ∂/∂x: [−1 0 1] along the row, [1 2 1] down
        v = (np.int32(top[c2]) + 2 * np.int32(mid[c2]) + np.int32(bottom[c2])) \
            - (np.int32(top[c0]) + 2 * np.int32(mid[c0]) + np.int32(bottom[c0]))
    if not rising:
        v = abs(v)
    return np.int32(min(max(v, 0), 255))


@njit(cache=True, error_model="numpy")
def _pick(flat: np.ndarray, h: int, w: int, segments: tuple[np.ndarray, np.ndarray],
          roi_x: float, scale_x: float, first: bool, previous_p_px: float,
          previous_d_px: float, previous_i: float, kp: float, kd: float, ki: float
          ) -> tuple[float, float, float, float]:
    """``choose_lane`` on the gradient image held in ``flat`` (``search_candidates``'
    layout)."""
    best_i = np.empty(w, np.int32)
    best_end = np.empty(w, np.int32)
    search_candidates(flat, h, w, segments, best_i, best_end,
                      np.empty(w + SIMD_BLOCK, flat.dtype))
    k = 0
    lam = math.nan
    if first:
        for x in range(1, w):
            if best_i[x] > best_i[k]:
                k = x
    else:
        for x in range(w):
            # The same float64 operations, in the same order, as distance_lambda on arrays.
            p_img = (np.float64(x) + 0.5) * scale_x - 0.5 + roi_x
            d_img = np.float64(best_end[x] - x) * scale_x
            value = kp * abs(p_img - previous_p_px) + kd * abs(d_img - previous_d_px) \
                + ki * (previous_i - np.float64(best_i[x]))
            if math.isnan(value):
                k, lam = x, value
                break
            if x == 0 or value < lam:
                k, lam = x, value
    return ((np.float64(k) + 0.5) * scale_x - 0.5 + roi_x,
            np.float64(best_end[k] - k) * scale_x, np.float64(best_i[k]), lam)


@njit(cache=True, error_model="numpy")
def choose_lane(gradient: np.ndarray, roi_x: float, scale_x: float, first: bool,
                previous_p_px: float, previous_d_px: float, previous_i: float, kp: float,
                kd: float, ki: float) -> tuple[float, float, float, float]:
    """The lane of one ROI from its gradient image, in one call (the detector's per-ROI
    path, which as a chain of small numpy calls cost as much as the search): the
    candidates (``candidates``), taken back to image pixels (``P`` of pixel centres ×
    ``scale_x`` + ``roi_x``, ``D`` × ``scale_x``), then in a ``first`` frame the largest
    ``I``, else the smallest λ (``distance_lambda``; first of equals, a NaN wins as in
    ``numpy.argmin``). Returns ``(P, D, I, λ)`` [px, px, -, -], λ NaN in a first frame."""
    h, w = gradient.shape
    flat = np.zeros(h * w + SIMD_BLOCK, np.int32)
    for r in range(h):
        for c in range(w):
            flat[r * w + c] = gradient[r, c]
    return _pick(flat, h, w, _build_segment_steps(h, w), roi_x, scale_x, first,
                 previous_p_px, previous_d_px, previous_i, kp, kd, ki)


@njit(cache=True, error_model="numpy")
def find_lane(small: np.ndarray, segments: tuple[np.ndarray, np.ndarray],
              horizontal_edges: bool, rising: bool, roi_x: float, scale_x: float,
              first: bool, previous_p_px: float, previous_d_px: float, previous_i: float,
              kp: float, kd: float, ki: float) -> tuple[float, float, float, float]:
    """``choose_lane`` of the Sobel (``sobel_into``) of the resampled crop ``small``: the
    detector's per-ROI kernel, one call after the resize; ``segments`` is
    ``segment_steps(*small.shape)``."""
    h, w = small.shape
    args = (segments, roi_x, scale_x, first, previous_p_px, previous_d_px, previous_i, kp,
            kd, ki)
    if max(h, w) <= UINT16_MAX_SAMPLES:  # every segment sum fits 16 bits
        flat16 = np.zeros(h * w + SIMD_BLOCK, np.uint16)
        sobel_into(small, horizontal_edges, rising, flat16)
        return _pick(flat16, h, w, *args)
    flat = np.zeros(h * w + SIMD_BLOCK, np.int32)
    sobel_into(small, horizontal_edges, rising, flat)
    return _pick(flat, h, w, *args)


@njit(cache=True, error_model="numpy")
def find_lane_in_crop(crop: np.ndarray, small_height: int, small_width: int,
                      segments: tuple[np.ndarray, np.ndarray], horizontal_edges: bool,
                      rising: bool, roi_x: float, scale_x: float, first: bool,
                      previous_p_px: float, previous_d_px: float, previous_i: float,
                      kp: float, kd: float, ki: float) -> tuple[float, float, float, float]:
    """``find_lane`` of the ROI crop ``crop`` resampled (``resample_into``) to
    ``small_height`` × ``small_width`` px (``resample_shape``): the detector's whole
    per-ROI path in one call; ``segments`` is ``segment_steps(small_height,
    small_width)``."""
    small = np.empty((small_height, small_width), np.uint8)
    resample_into(crop, small)
    return find_lane(small, segments, horizontal_edges, rising, roi_x, scale_x, first,
                     previous_p_px, previous_d_px, previous_i, kp, kd, ki)
