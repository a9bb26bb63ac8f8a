"""The planner's Fedorov exchange (``planning.plan_next_poses``, ``exchange=True``) against a
brute-force criterion: never below plain greedy over several (seed, n), and a local optimum —
no single swap of a chosen pose for a candidate raises log det of the hand-eye information
(issue 22: an exchange that accumulated only the last candidate's information passed the
single (seed, n) comparison)."""

import numpy as np
import pytest

from handeye_drake.estimation import observability as ob
from handeye_drake.estimation import planning as pl
from tests.estimation.test_planning import SR, ST, X_BT, X_CE, _candidates

#: A prior so weak that the planner's criterion is the data's log det (to ~1e-10).
WEAK = dict(prior_rotation_std=1e3, prior_translation_std=1e3)


def _per_candidate_information(C):
    H = ob.sample_jacobians(list(C), X_CE, X_BT, SR, ST)
    return np.einsum("kmi,kmj->kij", H, H)


def _log_det(I_k, chosen):
    """log det of the hand-eye marginal (Schur complement) of the chosen poses' information."""
    return np.linalg.slogdet(ob.marginal_information(I_k[list(chosen)].sum(axis=0)))[1]


def _log_det_default_prior(I_k, chosen):
    """The planner's criterion with its default prior (1 rad, 1 m on every component of X_EC
    and X_BT: the identity in [δθ_EC; δt_EC; δ_BT]): log det of the hand-eye marginal."""
    T = ob.reduced_coordinates(X_CE)[0]     # [δ_EC; δ_BT] -> [δ_CE; δ_BT]
    return np.linalg.slogdet(ob.marginal_information(
        T.T @ I_k[list(chosen)].sum(axis=0) @ T + np.eye(12)))[1]


CASES = [(0, 4), (1, 8), (2, 5), (3, 6), (5, 6), (6, 7)]


@pytest.mark.parametrize("seed, n", CASES)
def test_exchange_is_never_below_greedy_and_no_single_swap_improves_it(seed, n):
    C = _candidates(seed, 60)
    I_k = _per_candidate_information(C)
    plan = pl.plan_next_poses(C, X_CE, X_BT, (), SR, ST, n=n, **WEAK)
    greedy = pl.plan_next_poses(C, X_CE, X_BT, (), SR, ST, n=n, exchange=False, **WEAK)
    assert len(set(plan.indices)) == n
    best = _log_det(I_k, plan.indices)
    assert best >= _log_det(I_k, greedy.indices) - 1e-9
    # The gains listed are the log det increases of the set in its order (with the weak prior
    # the first ones are dominated by it: compare the total from 3 poses on, where the data
    # determine the hand-eye pose).
    assert sum(plan.log_det_gain[3:]) == pytest.approx(best - _log_det(I_k, plan.indices[:3]),
                                                       abs=1e-6)
    # Local optimality: every swap of one chosen pose for one other candidate.
    chosen = list(plan.indices)
    others = [j for j in range(len(C)) if j not in chosen]
    worst = max(_log_det(I_k, chosen[:p] + [j] + chosen[p + 1:])
                for p in range(n) for j in others)
    assert worst <= best + 1e-7, (worst, best)


def test_exchange_improves_on_greedy_somewhere():
    """Not a test that cannot fail the other way: on these cases the exchange finds a strictly
    better set than greedy at least once (greedy is 1 unit of log det short, typically)."""
    gains = []
    for seed, n in CASES:
        C = _candidates(seed, 60)
        I_k = _per_candidate_information(C)
        a = pl.plan_next_poses(C, X_CE, X_BT, (), SR, ST, n=n, **WEAK).indices
        b = pl.plan_next_poses(C, X_CE, X_BT, (), SR, ST, n=n, exchange=False, **WEAK).indices
        gains.append(_log_det(I_k, a) - _log_det(I_k, b))
    assert max(gains) > 0.01, gains


@pytest.mark.parametrize("seed, n", [(1, 8), (5, 6), (4, 5)])
def test_exchange_with_the_default_prior_is_a_local_optimum_above_greedy(seed, n):
    """The default prior, 120 candidates (where the broken exchange fell below greedy: seed 1,
    n = 8: 77.02 vs 77.09; seed 5, n = 6: 75.61 vs 76.34)."""
    C = _candidates(seed)
    I_k = _per_candidate_information(C)
    plan = pl.plan_next_poses(C, X_CE, X_BT, (), SR, ST, n=n)
    greedy = pl.plan_next_poses(C, X_CE, X_BT, (), SR, ST, n=n, exchange=False)
    best = _log_det_default_prior(I_k, plan.indices)
    assert sum(plan.log_det_gain) == pytest.approx(best - _log_det_default_prior(I_k, []),
                                                   abs=1e-6)
    assert best >= _log_det_default_prior(I_k, greedy.indices) - 1e-9
    chosen = list(plan.indices)
    others = [j for j in range(len(C)) if j not in chosen]
    worst = max(_log_det_default_prior(I_k, chosen[:p] + [j] + chosen[p + 1:])
                for p in range(n) for j in others)
    assert worst <= best + 1e-7, (worst, best)
