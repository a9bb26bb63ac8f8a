"""Tolerances and default noise values, in one place.

Every module of the package takes its numeric defaults from here, so a value has one meaning and
one unit everywhere (metres, radians, pixels unless the name says otherwise).
"""

from __future__ import annotations

import math

# ------------------------------------------------------------------------------------ tolerances
#: Largest max(‖RᵀR − I‖_F, |det R − 1|) of a matrix that counts as a rotation: loose enough for
#: poses stored in float32 or printed with 6 decimals, tight enough to catch a scaled or sheared
#: matrix.
ROTATION_TOLERANCE = 1e-5

#: Largest accepted positive scalar (periods, gains): its square must stay finite.
MAX_MAGNITUDE = 1e150
#: Largest accepted entry of a pose (m or the data's length unit): 100 000 km. Beyond it the
#: data is garbage or in the wrong unit, and products of poses would overflow.
MAX_POSE_MAGNITUDE = 1e8
#: Largest accepted noise standard deviation (rad, m, px): beyond it nothing is measured, and the
#: filters' variances (σ⁴ in products) would overflow.
MAX_SIGMA = 1e6

#: Smallest rotation angle (rad) of a motion the classical solvers accept: catches (near-)pure
#: translations, whose rotation axis is undefined.
MIN_ROTATION_ANGLE = 1e-3

#: Rotation axes all within this angle (rad) of their common direction count as parallel.
MIN_AXIS_ANGLE = math.radians(1.0)

# ------------------------------------------------------------------------------- camera noise
#: Default noise of a measured target pose X_CT: rotation-vector noise (rad per axis) and
#: translation noise (m per coordinate) — a good pose-from-image estimate at half a metre.
CAMERA_ROTATION_SIGMA = 0.002
CAMERA_TRANSLATION_SIGMA = 0.0005
#: Default pixel noise of a detected image point (px per coordinate).
PIXEL_SIGMA = 0.5

# ---------------------------------------------------------------------------- on-line filters
#: NIS gate probability of the error-state filters: a measurement whose normalized innovation
#: exceeds the χ² quantile of this probability is rejected.
GATE_PROBABILITY = 0.999
#: Gauss–Newton iterations of the iterated EKF update.
ITERATIONS = 3
#: Gate rejections in a row after which a filter takes its covariance, not the data, to be wrong
#: and inflates it (lock-out recovery).
MAX_CONSECUTIVE_REJECTIONS = 5
#: Innovations larger than this many standard deviations (√(NIS / dof)) are rejected by every
#: filter, gate or no gate: no mis-tuning explains them, only a wrong measurement.
GROSS_ERROR_SIGMAS = 1000.0
#: The filters' consistency test (``EstimatorBase.consistency_message``): after this many fused
#: measurements, a mean NIS above its 99.9 % bound and this many times its expectation (the
#: measurement dimension) means the reported σ are too small. The factor leaves room for the
#: mild model errors of a matched filter (linearization, correlated samples) while catching a
#: wrong noise model (e.g. a pose filter fed visual-odometry poses: mean NIS ≈ 5× expectation).
NIS_MIN_UPDATES = 30
NIS_TOLERANCE = 1.5
#: Standard deviation (deg) above which a direction of the hand-eye estimate counts as not
#: determined by the motions seen so far (see ``excitation``).
UNOBSERVABLE_STD_DEG = 5.0
