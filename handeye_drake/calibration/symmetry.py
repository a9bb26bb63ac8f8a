"""Which way round a symmetric board is in each view, decided by the robot's motion.

A chessboard whose inner-corner counts have an even sum, a symmetric circle grid, or an
asymmetric one with an even number of rows looks the same after a half turn (a square one also
after a quarter turn): OpenCV labels its points from whichever end suits the image, so in some
views the measured X_CT is the true one times a turn G of the board about its centre
(``vision.targets.target_symmetries``). Turning every view the same way changes X_BT (or X_ET)
but not the hand-eye answer; turning some views and not others makes the poses disagree by
centimetres. Nothing in an image can tell, but the robot can: the camera's motion between two
views and the flange's are conjugate (eye-in-hand: X_CiCj = X_CT_i X_CT_j⁻¹ is X_EiEj seen from
the camera; eye-to-hand: X_TiTj = X_CT_i⁻¹ X_CT_j is X_EiEj seen from the board), so they turn by
the same angle and slide by the same distance along their screw axes — for one labelling and
not, in general, for the others.

``resolve`` picks for every view the labelling whose motions agree best with the robot's against
all the other views (each view in turn as the reference, the most consistent assignment kept).
Two views decide their relative labelling when every other one costs at least ``DECIDED``
more (χ² units; a pair's cost is its angle difference over ``ANGLE_TOL_DEG`` squared plus, for
turns of 15° or more, its screw-slide difference over ``SLIDE_TOL_M`` squared, capped at ``PAIR_CAP`` so that a
bad pair cannot dominate). Views left undecided are dropped with the reason; the typical cause
is motions that turn the board by ~90° about its normal between views (then θ and 180° − θ give
the same angle and the same slide); the views joined by deciding pairs form groups whose labels
are fixed relative to each other, and only the largest group is kept. Numpy only.
"""

from __future__ import annotations

import math

import numpy as np

#: Angle and screw-slide tolerances of a pair (robot and detection errors of a real cell are
#: well below: ~0.05° and ~1 mm).
ANGLE_TOL_DEG = 1.0
SLIDE_TOL_M = 0.005
#: Largest cost one pair adds (a wrong labelling typically costs hundreds).
PAIR_CAP = 25.0
#: Extra cost (χ²) the next-best labelling of a view must have for the view to be decided.
DECIDED = 16.0


def _log_rotation(R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(angle (…,) in [0, π], unit axis (…, 3)) of rotation matrices (…, 3, 3)."""
    cos = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos)
    w = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0],
                  R[..., 1, 0] - R[..., 0, 1]], axis=-1)
    norm = np.linalg.norm(w, axis=-1, keepdims=True)
    axis = np.where(norm > 1e-9, w / np.maximum(norm, 1e-12), 0.0)
    # Near π the skew part vanishes: the axis is the column of R + I of largest norm.
    near_pi = angle > math.pi - 1e-3
    if np.any(near_pi):
        B = R[near_pi] + np.eye(3)
        k = np.argmax(np.linalg.norm(B, axis=-2), axis=-1)
        col = B[np.arange(len(B)), :, k]
        axis[near_pi] = col / np.maximum(np.linalg.norm(col, axis=-1, keepdims=True), 1e-12)
    return angle, axis


def _invariants(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(turn angle (…,) rad, |slide along the screw axis| (…,) m) of rigid motions (…, 4, 4)."""
    angle, axis = _log_rotation(X[..., :3, :3])
    return angle, np.abs(np.einsum("...i,...i->...", axis, X[..., :3, 3]))


def _inv(X: np.ndarray) -> np.ndarray:
    out = np.zeros_like(X)
    Rt = np.swapaxes(X[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, X[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def pair_costs(X_BE: np.ndarray, X_CT: np.ndarray, turns: np.ndarray, mode: str) -> np.ndarray:
    """(N, N, M) cost of labelling view j with turn m relative to view i (view i as measured,
    view j's X_CT multiplied by turns[m]⁻¹). ``turns``: (M, 4, 4), turns[0] the identity."""
    n, m = len(X_BE), len(turns)
    A = np.einsum("iab,jbc->ijac", _inv(X_BE), X_BE)               # X_EiEj
    a_angle, a_slide = _invariants(A)                              # (N, N)
    Xj = np.einsum("jab,mbc->jmac", X_CT, _inv(turns))             # (N, M, 4, 4)
    if mode == "eye_in_hand":
        B = np.einsum("iab,jmbc->ijmac", X_CT, _inv(Xj))           # X_CiCj
    else:
        B = np.einsum("iab,jmbc->ijmac", _inv(X_CT), Xj)           # X_TiTj
    b_angle, b_slide = _invariants(B)                              # (N, N, M)
    d_angle = np.degrees(np.abs(b_angle - a_angle[..., None])) / ANGLE_TOL_DEG
    screw = np.minimum(b_angle, a_angle[..., None]) > math.radians(15.0)
    d_slide = np.where(screw, np.abs(b_slide - a_slide[..., None]) / SLIDE_TOL_M, 0.0)
    cost = np.minimum(d_angle ** 2 + d_slide ** 2, PAIR_CAP)
    cost[np.arange(n), np.arange(n)] = 0.0
    return cost


def _compose_table(turns: np.ndarray) -> np.ndarray:
    """table[a, b] = index of turns[a]⁻¹ · turns[b] (a group: the board's turns)."""
    m = len(turns)
    table = np.zeros((m, m), int)
    for a in range(m):
        for b in range(m):
            P = _inv(turns[a]) @ turns[b]
            table[a, b] = int(np.argmin([np.abs(P - T).max() for T in turns]))
    return table


def resolve(X_BE, X_CT, turns, mode: str):
    """Labels of the views of a symmetric board from the robot's motion.

    Args:
        X_BE: (N, 4, 4) flange poses paired with the views (m).
        X_CT: (N, 4, 4) board poses as detected (m).
        turns: (M, 4, 4) the board's turns, turns[0] the identity (``target_symmetries``).
        mode: "eye_in_hand" or "eye_to_hand".

    Returns:
        (labels (N,) int: the turn to undo in each view, X_true = X_CT · turns[label]⁻¹;
        decided (N,) bool: the view's labelling is fixed relative to the others' by the
        motions — the views joined by pairs whose other labellings cost ≥ ``DECIDED`` more,
        the largest such group).
    """
    X_BE, X_CT, turns = (np.asarray(v, float) for v in (X_BE, X_CT, turns))
    n, m = len(X_BE), len(turns)
    if n < 2:
        return np.zeros(n, int), np.zeros(n, bool)
    cost = pair_costs(X_BE, X_CT, turns, mode)
    table = _compose_table(turns)
    best_labels, best_total = None, np.inf
    # A few references spread over the recording (the assignment rarely depends on which).
    for r in np.unique(np.linspace(0, n - 1, min(n, 8)).round().astype(int)):
        labels = np.argmin(cost[r], axis=1)
        labels[r] = 0
        # One pass of coordinate descent against all views.
        for _ in range(2):
            for j in range(n):
                totals = [cost[np.arange(n), j, table[labels, g]].sum()
                          - cost[j, j, table[labels[j], g]] for g in range(m)]
                labels[j] = int(np.argmin(totals))
        total = cost[np.arange(n)[:, None], np.arange(n)[None, :],
                     table[labels[:, None], labels[None, :]]].sum()
        if total < best_total - 1e-9:
            best_labels, best_total = labels.copy(), total
    labels = best_labels
    # A pair decides its relative labelling when every other one costs ≥ DECIDED more; the
    # views joined by deciding pairs have labels fixed relative to each other. Two groups not
    # joined could be turned against each other for free: only the largest is kept.
    rel = table[labels[:, None], labels[None, :]]                           # (N, N)
    chosen = np.take_along_axis(cost, rel[..., None], axis=2)[..., 0]
    others = np.where(np.arange(m)[None, None, :] == rel[..., None], np.inf, cost).min(axis=2)
    deciding = (others - chosen >= DECIDED) if m > 1 else np.ones((n, n), bool)
    deciding |= deciding.T
    group = np.arange(n)
    for i, j in zip(*np.nonzero(np.triu(deciding, 1))):
        gi, gj = group[i], group[j]
        if gi != gj:
            group[group == gj] = gi
    sizes = np.bincount(group, minlength=n)
    decided = group == np.argmax(sizes)
    # Undo a common turn: the label of most decided views is "as detected".
    common = np.bincount(labels[decided], minlength=m).argmax()
    labels = table[np.full(n, common), labels]
    return labels, decided


def undecided_reason(target_text: str) -> str:
    return (f"{target_text} looks the same after a turn and the robot's motion cannot tell which "
            "way round it is in this view (its motions to the other views turn the board by "
            "about 90° about its normal?): left out")
