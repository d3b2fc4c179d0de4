"""A heads-up text box drawn onto video frames (step, action, what the robot heard, task belief).

Pillow's bundled font, scaled to the frame height; a translucent dark box in the top-left corner keeps the text
readable over the lab floor. Frames too small for legible text (under 120 px high) are returned unchanged.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np

MIN_HEIGHT = 120


@functools.lru_cache(maxsize=8)
def _font(size: int):
    from PIL import ImageFont

    return ImageFont.load_default(size=size)


def annotate(frame: np.ndarray, lines: Sequence[str]) -> np.ndarray:
    """A copy of ``frame`` (H x W x 3 uint8) with ``lines`` drawn in a box at the top-left corner."""
    height = frame.shape[0]
    if height < MIN_HEIGHT or not lines:
        return frame
    from PIL import Image, ImageDraw

    image = Image.fromarray(np.ascontiguousarray(frame))
    draw = ImageDraw.Draw(image, "RGBA")
    font = _font(max(10, height // 34))
    margin = max(3, height // 120)
    boxes = [draw.textbbox((0, 0), line, font=font) for line in lines]
    line_height = max(box[3] - box[1] for box in boxes) + margin
    width = max(box[2] - box[0] for box in boxes)
    draw.rectangle(
        (margin, margin, 3 * margin + width, 2 * margin + line_height * len(lines)), fill=(20, 20, 24, 170)
    )
    for index, line in enumerate(lines):
        draw.text(
            (2 * margin, 1.5 * margin + index * line_height), line, font=font, fill=(245, 245, 245, 255)
        )
    return np.asarray(image)
