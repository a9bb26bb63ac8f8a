"""Two calibrations of one camera mount, compared: the difference of their hand-eye answers
(X_EC eye-in-hand, X_BC eye-to-hand), its σ from the two answers' own covariances, and a
verdict — consistent, or not with the likely cause.

The difference d = [log(R_a R_bᵀ); t_a − t_b] (rad about / m along the parent frame's axes, the
error state of ``calibration.json``: R = exp(δθ) R̂, t = t̂ + δt) has, the two sessions being
independent, covariance C_a + C_b; χ² = dᵀ (C_a + C_b)⁻¹ d on 6 degrees of freedom.
Each answer's σ holds the robot error that repeats over its recording
(``corners.systematic_robot_level``), so a χ² beyond the 99.9 % point says the mount moved (or
was re-mounted) between the sessions, not that σ forgot the robot's kinematic error.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from ..estimation.se3 import rotation_log
from .naming import hand_name

#: Probability of the χ²(6) point beyond which the two answers are not consistent.
CONSISTENT_PROBABILITY = 0.999
#: Largest calibration.json read (bytes): a larger file is not one this tool wrote.
MAX_JSON_BYTES = 50_000_000


@dataclass
class Comparison:
    """The result of ``compare``: ``difference`` [δθ (rad); δt (m)] of this answer from the
    other, its 6×6 ``covariance``, ``chi2`` on 6 dof against ``threshold``, ``consistent``,
    ``cause`` ("" when consistent) and ``text`` (one paragraph)."""
    mode: str
    difference: np.ndarray
    covariance: np.ndarray
    chi2: float
    threshold: float
    consistent: bool
    cause: str
    text: str
    other: str = ""

    @property
    def rotation_deg(self) -> float:
        return math.degrees(float(np.linalg.norm(self.difference[:3])))

    @property
    def translation_m(self) -> float:
        return float(np.linalg.norm(self.difference[3:]))

    def to_dict(self) -> dict:
        sd = np.sqrt(np.maximum(np.diag(self.covariance), 0.0))
        return {"other": self.other, "frame": hand_name(self.mode),
                "difference": {"rotation_deg": self.rotation_deg,
                               "translation_m": self.translation_m,
                               "vector": self.difference.tolist(),
                               "definition": "[log(R_this R_otherᵀ) rad; t_this − t_other m]"},
                "std": {"rotation_deg": np.degrees(sd[:3]).tolist(),
                        "translation_m": sd[3:].tolist(),
                        "covariance": self.covariance.tolist()},
                "chi2": self.chi2, "dof": 6, "threshold": self.threshold,
                "probability": CONSISTENT_PROBABILITY, "consistent": self.consistent,
                "cause": self.cause, "text": self.text}


def read_answer(source, name: str = "--compare"):
    """(mode, X 4×4, covariance 6×6, verdict status) of a ``calibration.json`` path or dict (or
    a ``CalibrationResult``); ValueError naming ``name`` when it is missing or not one."""
    return _answer(source, name)


def _answer(source, name: str) -> tuple[str, np.ndarray, np.ndarray, str]:
    """(mode, X 4×4, covariance 6×6, verdict status) of a ``CalibrationResult``, a
    ``calibration.json`` dict or a path to one; ValueError naming ``name``."""
    if hasattr(source, "X_hand") and hasattr(source, "covariance"):
        return (source.mode, np.asarray(source.X_hand, float),
                np.asarray(source.covariance, float), source.verdict.status)
    if isinstance(source, (str, Path)):
        path = Path(source)
        if path.is_dir():  # an output folder: its calibration.json
            if not (path / "calibration.json").is_file():
                raise ValueError(f"{name}: {path} is a folder without a calibration.json")
            path = path / "calibration.json"
        if not path.is_file():
            raise ValueError(f"{name}: no such file: {path}")
        if path.stat().st_size > MAX_JSON_BYTES:
            raise ValueError(f"{name}: {path} is larger than {MAX_JSON_BYTES} bytes; not a "
                             "calibration.json")
        try:
            source = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            raise ValueError(f"{name}: {path} is not a calibration.json (not JSON: "
                             f"{' '.join(str(e).split())})") from None
        name = f"{name} {path}"
    if not isinstance(source, dict):
        raise ValueError(f"{name}: expected a calibration.json object")
    if isinstance(source.get("rig"), dict) and isinstance(source.get("cameras"), dict):
        raise ValueError(f"{name}: a rig's calibration.json; give one camera's, "
                         f"NAME/calibration.json beside it (cameras: "
                         f"{', '.join(map(str, source['cameras']))})")
    mode = source.get("mode")
    if mode not in ("eye_in_hand", "eye_to_hand"):
        raise ValueError(f"{name}: not a calibration.json (no 'mode' eye_in_hand or "
                         "eye_to_hand)")
    key = hand_name(mode)
    try:
        pose = source[key]
        if isinstance(pose, list) and "camera" in source:
            # A rig camera's NAME/calibration.json: the 4×4 and the covariance (same error
            # state [δθ; δt]) beside it.
            X = np.asarray(pose, dtype=float)
            C = np.asarray(source["covariance"], dtype=float)
        else:
            X = np.asarray(pose["matrix"], dtype=float)
            C = np.asarray(pose["std"]["covariance"], dtype=float)
    except (KeyError, TypeError, ValueError):
        raise ValueError(f"{name}: not a calibration.json ({key}.matrix and "
                         f"{key}.std.covariance needed)") from None
    if X.shape != (4, 4) or C.shape != (6, 6) or not (np.all(np.isfinite(X))
                                                      and np.all(np.isfinite(C))):
        raise ValueError(f"{name}: {key} must hold a finite 4×4 matrix and 6×6 covariance")
    R = X[:3, :3]
    if np.max(np.abs(R.T @ R - np.eye(3))) > 1e-6 or np.linalg.det(R) <= 0:
        raise ValueError(f"{name}: {key}.matrix is not a rigid transform")
    C = 0.5 * (C + C.T)
    if np.min(np.linalg.eigvalsh(C)) <= 0:
        raise ValueError(f"{name}: {key}.std.covariance is not positive definite")
    status = (source.get("verdict") or {}).get("status", "") if isinstance(
        source.get("verdict"), dict) else ""
    return mode, X, C, str(status)


def compare(this, other, other_name: str = "--compare") -> Comparison:
    """Compares two answers for one camera mount: each a ``CalibrationResult``, a
    ``calibration.json`` dict or its path. Raises ValueError (naming ``other_name``) on an
    unreadable or different-mode other answer."""
    mode, X_a, C_a, status_a = _answer(this, "this calibration")
    mode_b, X_b, C_b, status_b = _answer(other, other_name)
    label = str(other) if isinstance(other, (str, Path)) else "the other calibration"
    if mode_b != mode:
        raise ValueError(f"{other_name}: {label} is {mode_b.replace('_', '-')}, this calibration "
                         f"is {mode.replace('_', '-')}: not the same mount")
    d = np.concatenate([rotation_log(X_a[:3, :3] @ X_b[:3, :3].T), X_a[:3, 3] - X_b[:3, 3]])
    C = C_a + C_b
    q = float(d @ np.linalg.solve(C, d))
    threshold = float(chi2.ppf(CONSISTENT_PROBABILITY, 6))
    consistent = q <= threshold
    sd = np.sqrt(np.diag(C))
    rot_sd = math.degrees(math.sqrt(float(np.sum(sd[:3] ** 2))))
    tr_sd = math.sqrt(float(np.sum(sd[3:] ** 2)))
    name = hand_name(mode)
    what = (f"{name} differs from {label}'s by {math.degrees(np.linalg.norm(d[:3])):.3g}° / "
            f"{1000 * np.linalg.norm(d[3:]):.3g} mm (σ of the difference "
            f"{rot_sd:.2g}° / {1000 * tr_sd:.2g} mm; χ² {q:.1f} on 6 dof, "
            f"{100 * CONSISTENT_PROBABILITY:g} % point {threshold:.1f})")
    caveat = ""
    if "FAIL" in (status_a, status_b):
        caveat = (" — but " + ("both verdicts are" if status_a == status_b else
                               ("this" if status_a == "FAIL" else "the other") + " verdict is")
                  + " FAIL: fix that first")
    if consistent:
        cause = ""
        text = f"consistent: {what}" + caveat
    else:
        cause = "mount_moved"
        # Which part moved: the larger of the rotation's and the translation's own χ².
        q_r = float(d[:3] @ np.linalg.solve(C[:3, :3], d[:3]))
        q_t = float(d[3:] @ np.linalg.solve(C[3:, 3:], d[3:]))
        part = "rotation" if q_r >= q_t else "translation"
        text = (f"not consistent: the mount moved between the sessions ({part} mostly) — {what}; "
                "each σ holds the robot's own repeating error, so a camera knocked, re-mounted "
                "or a bracket that slipped is the likely cause; if nothing was touched, the two "
                "sessions covered parts of the workspace where the robot's kinematic error "
                "differs (give both the same poses, or a larger --robot-accuracy)" + caveat)
    return Comparison(mode, d, C, q, threshold, consistent, cause, text, label)


__all__ = ["CONSISTENT_PROBABILITY", "Comparison", "compare", "read_answer"]
