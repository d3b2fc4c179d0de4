"""A heads-up text box drawn onto video frames (step, action, what the robot heard, task belief).

Pillow's bundled font, scaled to the frame height; a translucent dark box in the top-left corner keeps the text
readable over the lab floor. Frames too small for legible text (under 120 px high) are returned unchanged.

Each line is rasterised once into an alpha mask and turned into its "layer" over the box: per pixel, the weight
left to the frame's pixel and the colour added (box and text composited), cached (the heads-up text changes once
per macro step, only the time line every frame). A frame then costs one
multiply-add over the box: ``out = rint(frame * keep + colour)``, the same arithmetic as blending the box and then
the text, regrouped.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np

MIN_HEIGHT = 120
BOX_COLOUR = np.array([20.0, 20.0, 24.0])
BOX_ALPHA = 170 / 255
TEXT_COLOUR = np.array([245.0, 245.0, 245.0])


@functools.lru_cache(maxsize=8)
def _font(size: int):
    from PIL import ImageFont

    return ImageFont.load_default(size=size)


@functools.lru_cache(maxsize=512)
def _line_mask(text: str, size: int) -> np.ndarray:
    """The text's coverage (0..1, float32), cropped at the left and top as Pillow places it at the origin."""
    from PIL import Image, ImageDraw

    font = _font(size)
    left, top, right, bottom = font.getbbox(text)
    image = Image.new("L", (max(1, right), max(1, bottom)))
    ImageDraw.Draw(image).text((0, 0), text, font=font, fill=255)
    mask = np.asarray(image, dtype=np.float32) / 255.0
    mask.setflags(write=False)
    return mask


@functools.lru_cache(maxsize=512)
def _line_layer(text: str, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Over the text's rectangle: the frame pixel's weight (H x W x 1) and the colour added (H x W x 3), float32.
    Blending the box (``b = f + a (B - f)``) and then the text (``b + m (T - b)``) is ``f * keep + colour`` with
    ``keep = (1 - a)(1 - m)`` and ``colour = a B (1 - m) + m T``."""
    mask = _line_mask(text, size)[..., None]
    keep = ((1.0 - BOX_ALPHA) * (1.0 - mask)).astype(np.float32)
    colour = (BOX_ALPHA * BOX_COLOUR * (1.0 - mask) + mask * TEXT_COLOUR).astype(np.float32)
    keep.setflags(write=False)
    colour.setflags(write=False)
    return keep, colour


@functools.lru_cache(maxsize=16)
def _box_layer(rows: int, cols: int) -> tuple[np.ndarray, np.ndarray]:
    """The empty box's layer: every frame pixel kept at ``1 - BOX_ALPHA``, ``BOX_ALPHA * BOX_COLOUR`` added."""
    keep = np.full((rows, cols, 1), 1.0 - BOX_ALPHA, np.float32)
    colour = np.broadcast_to((BOX_ALPHA * BOX_COLOUR).astype(np.float32), (rows, cols, 3)).copy()
    keep.setflags(write=False)
    colour.setflags(write=False)
    return keep, colour


def annotate(frame: np.ndarray, lines: Sequence[str]) -> np.ndarray:
    """A copy of ``frame`` (H x W x 3 uint8) with ``lines`` drawn in a box at the top-left corner."""
    height, width = frame.shape[:2]
    if height < MIN_HEIGHT or not lines:
        return frame
    size = max(10, height // 34)
    margin = max(3, height // 120)
    masks = [_line_mask(line, size) for line in lines]
    line_height = max(mask.shape[0] for mask in masks) + margin
    text_width = max(mask.shape[1] for mask in masks)
    x1 = min(width, 3 * margin + text_width + 1)
    y1 = min(height, 2 * margin + line_height * len(lines) + 1)
    rows, cols = y1 - margin, x1 - margin
    base_keep, base_colour = _box_layer(rows, cols)
    keep, colour = base_keep.copy(), base_colour.copy()
    for index, line in enumerate(lines):
        top = int(1.5 * margin + index * line_height) - margin
        left = margin  # 2 * margin in frame coordinates
        line_keep, line_colour = _line_layer(line, size)
        n_rows = min(line_keep.shape[0], rows - top)
        n_cols = min(line_keep.shape[1], cols - left)
        if n_rows <= 0 or n_cols <= 0:
            continue
        keep[top : top + n_rows, left : left + n_cols] = line_keep[:n_rows, :n_cols]
        colour[top : top + n_rows, left : left + n_cols] = line_colour[:n_rows, :n_cols]
    out = frame.copy()
    box = out[margin:y1, margin:x1]
    blended = np.multiply(box, keep, dtype=np.float32)
    blended += colour
    np.rint(blended, out=blended)
    box[...] = blended.astype(np.uint8)
    return out
