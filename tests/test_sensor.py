"""The camera model's shortcuts against the computation they shorten (numpy, no Mitsuba)."""

from __future__ import annotations

import numpy as np
import pytest

from datagen.core.camera import Intrinsics
from datagen.render.sensor import sun_glare


@pytest.mark.parametrize(("size", "hfov_deg", "sun_cam"), [
    ((2048, 1080), 55.0, (0.02, 0.01, 1.0)),  # the sun near the centre
    ((2048, 1080), 55.0, (0.6, 0.4, 1.0)),  # just outside a corner
    ((2048, 1080), 55.0, (-0.2, 0.25, 1.0)),
    ((1000, 501), 75.0, (0.8, -0.3, 0.5)),  # far outside, within reach
    ((1000, 501), 75.0, (0.3, -0.1, 1.0)),
    ((640, 338), 15.0, (0.05, -0.02, 1.0)),  # a narrow lens: a fine grid
], ids=["centre", "corner", "inside", "outside", "1000px", "narrow"])
def test_glare_on_a_coarse_grid_is_the_glare_at_every_pixel_within_one_percent_of_its_peak(size, hfov_deg,
                                                                                         sun_cam) -> None:
    w, h = size
    k = Intrinsics.from_hfov_deg(w, h, hfov_deg)
    coarse, inside = sun_glare((h, w), k, np.array(sun_cam), 0.8, 3.0)
    fine, inside_fine = sun_glare((h, w), k, np.array(sun_cam), 0.8, 3.0, step=1)
    assert coarse.shape == fine.shape == (h, w, 3) and inside == inside_fine
    error = np.abs(coarse - fine)
    assert error.max() <= 0.01 * fine.max(), error.max() / fine.max()
    assert error.mean() <= 0.003 * fine.mean()
    assert abs(coarse.sum() / fine.sum() - 1.0) < 0.003  # the same light in the image


def test_no_glare_where_the_sun_is_beyond_its_reach() -> None:
    k = Intrinsics.from_hfov_deg(640, 338, 55.0)
    assert sun_glare((338, 640), k, np.array([0.0, 0.0, -1.0]), 0.8, 3.0) == (None, False)
