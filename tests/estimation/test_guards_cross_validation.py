"""Cross-validation of the corner-level fit predicts each image from a fit that never saw it.

Independent of how the fit is done: if image k is left out, its prediction does not depend on
its own corners, so shifting all of them by s and by −s changes its squared prediction error by
exactly ∓2 s·ē + |s|² (ē its mean error): e(+s)² + e(−s)² = 2 e² + 2 |s|² to rounding. A fit that
kept image k would follow the shift a little and break the identity."""

import numpy as np
import pytest

from handeye_drake.estimation import reprojection as rp

from .test_reprojection import V_TRUE, _scene


@pytest.fixture(scope="module")
def scene():
    rng = np.random.default_rng(11)
    data, X_H, X_F = _scene(rng, 9)
    fit = rp.fit_corners(data, X_H, X_F, V_TRUE, "focal", pixel_sigma0=0.1)
    assert fit.image_used.all()
    return data, fit


def _shifted(data, k, s):
    pts = data.image_points.copy()
    pts[data.image == k] += s
    return rp.CornerData(data.X_R, data.image, data.object_points, pts)


@pytest.mark.parametrize("folds", [None, 3])
def test_left_out_images_are_predicted_without_their_own_corners(scene, folds):
    data, fit = scene
    base = rp.cross_validate(data, fit, folds=folds)
    assert base["method"] == ("leave-one-out" if folds is None else "3-fold")
    s = np.array([1.5, -1.0])
    for k in (0, 4):
        e0 = base["image_rms_px"][k]
        plus = rp.cross_validate(_shifted(data, k, s), fit, folds=folds)["image_rms_px"][k]
        minus = rp.cross_validate(_shifted(data, k, -s), fit, folds=folds)["image_rms_px"][k]
        assert plus ** 2 + minus ** 2 == pytest.approx(2 * e0 ** 2 + 2 * s @ s, rel=1e-6)


def test_left_out_error_exceeds_the_in_fit_residual(scene):
    # Predicting an unseen image (no per-image pose error fitted) is worse than fitting it.
    data, fit = scene
    cv = rp.cross_validate(data, fit)
    assert cv["rms_px"] > fit.rms_px
    per = cv["image_rms_px"]
    assert np.all(np.isfinite(per)) and len(per) == data.num_images
    # The overall figure is the RMS over every predicted corner.
    n = np.bincount(data.image[fit.corner_used], minlength=data.num_images)
    assert cv["rms_px"] == pytest.approx(np.sqrt(np.sum(n * per ** 2) / n.sum()), rel=1e-9)
