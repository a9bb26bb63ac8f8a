"""The session's stop rule needs the rotation σ *and* the translation σ at their targets (here a
loose rotation target reached from the first batch, a translation target not yet), and the
pairing-shift rule names a shift only when its angle mismatch is ≤ ¼ of the order given's and
≤ 2° (scores planted on both sides of each bound)."""

import math

import numpy as np
import pytest

from handeye_drake.calibration import pairing
from handeye_drake.calibration.session import CalibrationSession

from .test_session import GUESS, OPTIONS, samples


def test_stop_needs_both_rotation_and_translation_at_target():
    target = (5.0, 0.5)                  # deg: reached at once; mm: not before ~16 samples
    s = CalibrationSession(*target, OPTIONS, batch_every=3, hand_eye_guess=GUESS)
    rotation_only = False
    for x in samples(24, seed=5)[:11]:
        st = s.add(*x)
        if st.source != "batch":
            continue
        t = s.result.covariance
        rot = math.degrees(math.sqrt(np.trace(t[:3, :3])))
        tra = 1000 * math.sqrt(np.trace(t[3:, 3:]))
        assert st.stop == (rot <= target[0] and tra <= target[1] and st.verdict == "OK")
        rotation_only |= st.verdict == "OK" and rot <= target[0] and tra > target[1]
    assert rotation_only          # the samples tell "and" from "or"


@pytest.mark.parametrize("scores, named", [
    ({-1: 1.1, 0: 1.0, 1: 0.26}, None),          # better, but not 4× better
    ({-1: 1.1, 0: 1.0, 1: 0.24}, 1),             # 4× better
    ({-1: 2.1, 0: 20.0, 1: 3.0}, None),          # 6× better, but 3° off: no pairing fits
    ({-1: 1.9, 0: 20.0, 1: 3.0}, -1),
    ({-1: 0.5, 0: 0.5, 1: 0.6}, None),
])
def test_pairing_shift_bounds(monkeypatch, scores, named):
    monkeypatch.setattr(pairing, "shift_scores", lambda *a, **k: dict(scores))
    found = pairing.pairing_shift(None, None)
    assert (None if found is None else found[0]) == named
