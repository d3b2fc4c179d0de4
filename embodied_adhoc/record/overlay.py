"""A heads-up text box drawn onto video frames (step, action, what the robot heard, task belief).

Pillow's bundled font, scaled to the frame height; a translucent dark box in the top-left corner keeps the text
readable over the lab floor. Frames too small for legible text (under 120 px high) are returned unchanged.

Each line is rasterised once into an alpha mask and cached (the heads-up text changes once per macro step, only
the time line every frame); a frame then costs two numpy blends over the box instead of a full-frame Pillow
round trip.
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
    out = frame.copy()
    box = out[margin:y1, margin:x1].astype(np.float32)
    box += BOX_ALPHA * (BOX_COLOUR - box)
    for index, mask in enumerate(masks):
        top = int(1.5 * margin + index * line_height) - margin
        left = margin  # 2 * margin in frame coordinates
        rows = min(mask.shape[0], box.shape[0] - top)
        cols = min(mask.shape[1], box.shape[1] - left)
        if rows <= 0 or cols <= 0:
            continue
        alpha = mask[:rows, :cols, None]
        region = box[top : top + rows, left : left + cols]
        region += alpha * (TEXT_COLOUR - region)
    out[margin:y1, margin:x1] = np.rint(box).astype(np.uint8)
    return out
