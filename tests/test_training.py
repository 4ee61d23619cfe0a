"""How Ultralytics' trainer sees a label (datagen.core.training): the resize and centring onto
the square input, the 2 px rule and the anchor grid, against brute force."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from datagen.core.training import ANCHOR_STRIDES, ASSIGNABLE_SIDE_PX, SIDE_TOLERANCE_PX, TrainView

from .strategies import finite

TABLE1 = TrainView(2048, 1080, 864)


def test_table1_frames_become_864x456_centred_on_the_864_square() -> None:
    assert TABLE1.resized == (864, 456)  # ceil(1080 * 0.421875) = ceil(455.625)
    assert TABLE1.scale == (864 / 2048, 456 / 1080)
    assert TABLE1.offset == (0.0, 204.0)
    np.testing.assert_allclose(TABLE1.to_train([0, 0, 2048, 1080]), [0, 204, 864, 660])


@given(w=st.integers(16, 4096), h=st.integers(16, 4096), imgsz=st.sampled_from([320, 640, 864, 1280]))
def test_the_long_side_becomes_imgsz_and_the_image_sits_centred(w, h, imgsz) -> None:
    view = TrainView(w, h, imgsz)
    w_t, h_t = view.resized
    assert max(w_t, h_t) == imgsz
    r = imgsz / max(w, h)
    assert (w_t, h_t) == (min(math.ceil(w * r), imgsz), min(math.ceil(h * r), imgsz))
    ox, oy = view.offset
    assert ox + w_t / 2 == imgsz / 2 and oy + h_t / 2 == imgsz / 2


@given(w=st.integers(64, 4096), h=st.integers(64, 4096), imgsz=st.sampled_from([320, 640, 864]),
       min_box=st.floats(0.5, 64.0, **finite))
def test_the_minimum_label_size_is_min_box_px_at_the_training_size(w, h, imgsz, min_box) -> None:
    view = TrainView(w, h, imgsz)
    mw, mh = view.min_label_size_px(min_box)
    t = view.to_train([100.0, 50.0, 100.0 + mw, 50.0 + mh])
    np.testing.assert_allclose([t[2] - t[0], t[3] - t[1]], [min_box, min_box], rtol=1e-12)


def brute_force_anchor(box_train: np.ndarray, imgsz: int) -> bool:
    """Every anchor centre of every stride, checked one by one (Ultralytics' make_anchors grid)."""
    for s in ANCHOR_STRIDES:
        c = (np.arange(imgsz // s) + 0.5) * s
        xs = c[(c - box_train[0] > 1e-9) & (box_train[2] - c > 1e-9)]
        ys = c[(c - box_train[1] > 1e-9) & (box_train[3] - c > 1e-9)]
        if xs.size and ys.size:
            return True
    return False


@given(x=st.floats(-20.0, 2060.0, **finite), y=st.floats(-20.0, 1100.0, **finite),
       w=st.floats(0.0, 80.0, **finite), h=st.floats(0.0, 80.0, **finite))
def test_has_anchor_equals_a_brute_force_search_of_the_anchor_grid(x, y, w, h) -> None:
    box = np.array([x, y, x + w, y + h])
    assert bool(TABLE1.has_anchor(box)) == brute_force_anchor(TABLE1.to_train(box), 864)


@given(x=st.floats(30.0, 2000.0, **finite), y=st.floats(30.0, 1030.0, **finite),
       extra=st.tuples(st.floats(0.0, 40.0, **finite), st.floats(0.0, 40.0, **finite)))
def test_a_box_of_at_least_8_training_px_reaches_the_loss(x, y, extra) -> None:
    """8 px (the finest stride) at the training size: over 2 px, and an anchor centre inside."""
    mw, mh = TABLE1.min_label_size_px(8.0 * (1 + 1e-9))
    box = np.array([x - mw / 2 - extra[0], y - mh / 2 - extra[1], x + mw / 2 + extra[0], y + mh / 2 + extra[1]])
    assert TABLE1.survives(box) and TABLE1.has_anchor(box) and TABLE1.reaches_loss(box)


@given(x=st.floats(60.0, 1980.0, **finite), y=st.floats(60.0, 1020.0, **finite),
       extra=st.tuples(st.floats(0.0, 40.0, **finite), st.floats(0.0, 40.0, **finite)))
def test_a_box_grown_to_the_assignable_side_is_learnable(x, y, extra) -> None:
    """A box grown to exactly ASSIGNABLE_SIDE_PX at the training size (as labels.min_box_px grows
    it, in original pixels) or larger is learnable: the ulps lost on the way do not count."""
    mw, mh = TABLE1.min_label_size_px(ASSIGNABLE_SIDE_PX)
    box = np.array([x - mw / 2 - extra[0], y - mh / 2 - extra[1], x + mw / 2 + extra[0], y + mh / 2 + extra[1]])
    assert TABLE1.assignable(box) and TABLE1.learnable(box)


@given(x=st.floats(60.0, 1980.0, **finite), y=st.floats(60.0, 1020.0, **finite),
       short=st.floats(2.5, ASSIGNABLE_SIDE_PX - 2 * SIDE_TOLERANCE_PX, **finite),
       other=st.floats(2.5, 200.0, **finite),
       axis=st.integers(0, 1))
def test_a_side_under_the_assignable_side_is_not_learnable_though_it_reaches_the_loss(x, y, short, other,
                                                                                       axis) -> None:
    """The untrained head's assigner gives such a box no target (datagen.core.training, rule 5);
    a side within SIDE_TOLERANCE_PX of the assignable side counts as it (a label line's rounding)."""
    sides = np.array([other, other], dtype=float)
    sides[axis] = short
    w, h = sides / np.array(TABLE1.scale)
    box = np.array([x, y, x + w, y + h])
    assert not TABLE1.assignable(box) and not TABLE1.learnable(box)


@given(x=st.floats(30.0, 2000.0, **finite), y=st.floats(30.0, 1030.0, **finite),
       side=st.floats(0.0, 2.0 - 1e-6, **finite), other=st.floats(0.0, 60.0, **finite), axis=st.integers(0, 1))
def test_a_side_under_2_training_px_is_dropped(x, y, side, other, axis) -> None:
    """(A side of exactly 2 px lands on either side of Ultralytics' ``> 2`` by the float
    rounding of the box corners, in Ultralytics as here: it is left out.)"""
    sides = np.array([other, other], dtype=float)
    sides[axis] = side
    w, h = sides / np.array(TABLE1.scale)
    box = np.array([x, y, x + w, y + h])
    assert not TABLE1.survives(box) and not TABLE1.learnable(box)


def test_very_elongated_boxes_are_dropped() -> None:
    sx, sy = TABLE1.scale
    assert TABLE1.survives([100, 100, 100 + 250 / sx, 100 + 3 / sy])  # 250 x 3 at the training size: 83
    assert not TABLE1.survives([100, 100, 100 + 310 / sx, 100 + 3 / sy])  # 103


@pytest.mark.parametrize("args", [(0, 1080, 864), (2048, -1, 864), (2048, 1080, 0)])
def test_sizes_must_be_positive(args) -> None:
    with pytest.raises(ValueError, match="sizes must be positive"):
        TrainView(*args)
