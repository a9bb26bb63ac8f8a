"""Starting an on-line estimator: the registry of estimator types, the two-motion classical
solution, and the replay of the self-calibration samples — shared by the Drake calibrator and the
batch code paths.

    X_CE0 = two_motion_estimate(X_BE_keys, X_CT_keys)            # M + 1 key frames → M motions
    est = start_estimator(config, X_CE0, X_BE_samples, X_CT_samples)

Frames: X_BE end-effector in robot base, X_CT target in camera, X_CE the paper's X (E in C).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .configs import ESTIMATOR_CONFIGS, ManifoldFilter, PaperFilter, TargetFilter
from .kalman import HandEyeKalmanFilter
from .linear_model import relative_motions_unchecked
from .manifold import HandEyeTargetFilter, ManifoldHandEyeFilter
from .solvers import solve_ax_xb

#: Estimator class of each settings type.
ESTIMATOR_TYPES = {PaperFilter: HandEyeKalmanFilter, ManifoldFilter: ManifoldHandEyeFilter,
                   TargetFilter: HandEyeTargetFilter}

#: How much wider (per standard deviation) the initial covariance is when the two-motion solution
#: failed and the estimator starts from the user's guess instead.
GUESS_STD_FACTOR = 10.0


def estimator_type(config) -> type:
    """The estimator class for a settings object of ``configs``."""
    try:
        return ESTIMATOR_TYPES[type(config)]
    except KeyError:
        raise ValueError(f"estimator: expected settings of type "
                         f"{', '.join(c.__name__ for c in ESTIMATOR_CONFIGS)}, got "
                         f"{type(config).__name__}") from None


def make_estimator(config, X_CE_init, **kwargs):
    """``estimator_type(config)(config, X_CE_init, **kwargs)``."""
    return estimator_type(config)(config, X_CE_init, **kwargs)


def two_motion_estimate(X_BE_keys, X_CT_keys, method: str = "daniilidis") -> np.ndarray:
    """X_CE from the M ≥ 2 motions between M + 1 key frames (the self-calibration motions'
    start and end poses), with a classical solver (``solvers.solve_ax_xb``; measured rotation
    blocks are projected onto SO(3)). Raises ValueError when the motions do not determine X
    (pure translations, parallel axes, inconsistent angles)."""
    A, B = relative_motions_unchecked(np.asarray(X_BE_keys, dtype=float),
                                      np.asarray(X_CT_keys, dtype=float))
    return solve_ax_xb(list(A), list(B), method, orthonormalize_inputs=True)


@dataclass
class StartResult:
    """What ``start_estimator`` did: the estimator (after the replay), where it started, how many
    samples it replayed, and whether it used the samples it was given (replay or ML start-up),
    the last one included."""
    estimator: object
    X_CE_start: np.ndarray
    replayed: int
    used_samples: bool


def start_estimator(config, X_CE_start, X_BE_samples=(), X_CT_samples=(),
                    from_guess: bool = False) -> StartResult:
    """Builds the estimator at ``X_CE_start`` (the two-motion solution) and, if its settings ask
    for it, replays the samples recorded during the self-calibration motions through
    ``update``. ``ManifoldFilter(start="ml")`` starts instead from the outlier-screened
    maximum-likelihood estimate (and covariance) of the motions between those samples.
    ``from_guess``: X_CE_start is only the user's guess (the two-motion solution failed): the
    initial standard deviations are ``GUESS_STD_FACTOR`` times wider."""
    config = config.validated()
    kind = estimator_type(config)
    samples = list(zip(X_BE_samples, X_CT_samples))
    if from_guess:
        config = replace(config, initial_variances=[
            v * GUESS_STD_FACTOR**2 for v in config.initial_variances])
    if isinstance(config, ManifoldFilter) and config.start == "ml" and not from_guess \
            and len(samples) >= 3:
        A, B = relative_motions_unchecked(np.array([s[0] for s in samples]),
                                          np.array([s[1] for s in samples]))
        try:
            est = ManifoldHandEyeFilter.from_motions(config, list(A), list(B))
            # The replay of the same samples would count them twice.
            est._update(*samples[-1])
            return StartResult(est, est.X_CE, 0, True)
        except ValueError:
            pass  # too little motion for the ML start: the two-motion start below
    est = kind(config, X_CE_start)
    replayed = 0
    if config.replay_self_calibration:
        for X_BE, X_CT in samples:
            est._update(X_BE, X_CT)
            replayed += 1
    return StartResult(est, np.array(X_CE_start, dtype=float), replayed, replayed > 0)
