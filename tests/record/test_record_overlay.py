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
