"""The video's heads-up text: drawn in the top-left box, frame size kept, tiny frames left alone."""

import numpy as np

from embodied_adhoc.record.overlay import annotate


def test_annotate_draws_text_in_the_corner_only():
    frame = np.full((240, 320, 3), 200, np.uint8)
    out = annotate(frame, ["step 3: locate human", "P(task): [0, 1, 2] 0.91"])
    assert out.shape == frame.shape and out.dtype == np.uint8
    assert (out[:40, :150] != 200).any()  # box and text in the corner
    assert (out[200:, 200:] == 200).all()  # the rest untouched
    assert (frame == 200).all()  # the input is not modified


def test_small_frames_are_returned_unchanged():
    frame = np.zeros((48, 64, 3), np.uint8)
    assert annotate(frame, ["hello"]) is frame


def _sequential_blend(frame, lines):
    """The heads-up box as first written: blend the box, then each line's text over it, in float32."""
    from embodied_adhoc.record.overlay import BOX_ALPHA, BOX_COLOUR, TEXT_COLOUR, _line_mask

    height, width = frame.shape[:2]
    size, margin = max(10, height // 34), max(3, height // 120)
    masks = [_line_mask(line, size) for line in lines]
    line_height = max(mask.shape[0] for mask in masks) + margin
    x1 = min(width, 3 * margin + max(mask.shape[1] for mask in masks) + 1)
    y1 = min(height, 2 * margin + line_height * len(lines) + 1)
    out = frame.copy()
    box = out[margin:y1, margin:x1].astype(np.float32)
    box += BOX_ALPHA * (BOX_COLOUR - box)
    for index, mask in enumerate(masks):
        top = int(1.5 * margin + index * line_height) - margin
        rows, cols = min(mask.shape[0], box.shape[0] - top), min(mask.shape[1], box.shape[1] - margin)
        region = box[top : top + rows, margin : margin + cols]
        region += mask[:rows, :cols, None] * (TEXT_COLOUR - region)
    out[margin:y1, margin:x1] = np.rint(box).astype(np.uint8)
    return out


def test_the_cached_layers_draw_what_blending_box_then_text_draws():
    rng = np.random.default_rng(5)
    for height, width in ((480, 640), (130, 160)):  # the text box clipped by a narrow frame too
        frame = rng.integers(0, 256, (height, width, 3), dtype=np.uint8)
        for t in range(3):
            lines = [
                "hotspot | balls in container 1/3",
                "P(task): [0, 1, 2] 0.91  [1, 2, 3] 0.09",
                f"t = {t}.5 s",
            ]
            got, want = annotate(frame, lines), _sequential_blend(frame, lines)
            assert np.abs(got.astype(int) - want).max() <= 1  # float rounding of the regrouped sum at most
            assert (got != want).mean() < 1e-3
