"""Long-run numerical health of ``HandEyeKalmanFilter``.

    python benchmarks/filter_long_run.py [--updates N] [--seed S] [--check-every M]

Feeds the paper's filter N (default 10**6) random small motion pairs (robot rotations of a few
degrees about random axes, translations of a few centimetres; camera motions A = X B X⁻¹ with the
paper's additive noise on R_A's coefficients and on t_A) and checks, every M updates (default
10**5) and at the end, that the 12×12 covariance is symmetric positive semi-definite and the
state finite. Prints the smallest eigenvalue, the asymmetry, the errors of the estimate against
the true X_CE and the update rate. Exit status 1 if a check fails.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from handeye_drake.estimation.configs import PaperFilter  # noqa: E402
from handeye_drake.estimation.errors import rotation_error_deg  # noqa: E402
from handeye_drake.estimation.kalman import HandEyeKalmanFilter  # noqa: E402
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp  # noqa: E402

#: Noise of the simulated camera motions (the paper's model) and the filter's assumed noise.
ROTATION_SIGMA = 1e-3
TRANSLATION_SIGMA = 1e-3


def covariance_health(P: np.ndarray) -> dict:
    """Smallest eigenvalue, largest eigenvalue and max |P − Pᵀ| of a covariance."""
    eig = np.linalg.eigvalsh(0.5 * (P + P.T))
    return {"min_eigenvalue": float(eig[0]), "max_eigenvalue": float(eig[-1]),
            "asymmetry": float(np.abs(P - P.T).max())}


def run(updates: int = 10**6, seed: int = 0, check_every: int = 10**5, report=None) -> dict:
    """Runs the filter for ``updates`` motion pairs; returns the final figures and the list of
    periodic checks. A check fails when the state or covariance is not finite, the asymmetry
    exceeds 1e-12 · max(1, ‖P‖) or the smallest eigenvalue is below −1e-12 · max(1, ‖P‖)."""
    rng = np.random.default_rng(seed)
    X_CE = make_transform(rotation_exp(rng.normal(size=3)), 0.1 * rng.normal(size=3))
    X_init = make_transform(rotation_exp(0.05 * rng.normal(size=3)) @ X_CE[:3, :3],
                            X_CE[:3, 3] + 0.01 * rng.normal(size=3))
    X_CE_inv = inverse(X_CE)
    kf = HandEyeKalmanFilter(PaperFilter(rotation_coefficient_sigma=ROTATION_SIGMA,
                                         translation_sigma=TRANSLATION_SIGMA,
                                         initial_variances=[1.0] * 12), X_init)
    # Draw the random motions in blocks (vectorized) to keep the loop about the filter itself.
    block = 10_000
    checks, failures = [], []
    start = time.perf_counter()
    done = 0
    while done < updates:
        n = min(block, updates - done)
        B = np.zeros((n, 4, 4))
        B[:, 3, 3] = 1.0
        B[:, :3, :3] = Rotation.from_rotvec(np.radians(3.0) * rng.normal(size=(n, 3))).as_matrix()
        B[:, :3, 3] = 0.03 * rng.normal(size=(n, 3))
        A = X_CE @ B @ X_CE_inv
        A[:, :3, :3] += ROTATION_SIGMA * rng.normal(size=(n, 3, 3))
        A[:, :3, 3] += TRANSLATION_SIGMA * rng.normal(size=(n, 3))
        for k in range(n):
            kf.update_motion(A[k], B[k])
            done += 1
            if done % check_every == 0 or done == updates:
                P, x = kf.covariance, kf.state
                health = covariance_health(P)
                scale = max(1.0, health["max_eigenvalue"])
                ok = (bool(np.all(np.isfinite(P)) and np.all(np.isfinite(x)))
                      and health["asymmetry"] <= 1e-12 * scale
                      and health["min_eigenvalue"] >= -1e-12 * scale)
                X = kf.X_CE
                entry = {"updates": done, **health,
                         "rotation_error_deg": rotation_error_deg(X_CE, X),
                         "translation_error": float(np.linalg.norm(X[:3, 3] - X_CE[:3, 3])),
                         "ok": ok}
                checks.append(entry)
                if not ok:
                    failures.append(entry)
                if report is not None:
                    report(entry)
    elapsed = time.perf_counter() - start
    return {"updates": updates, "seconds": elapsed, "updates_per_second": updates / elapsed,
            "final": checks[-1], "checks": checks, "failures": failures}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--updates", type=int, default=10**6)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--check-every", type=int, default=10**5)
    args = parser.parse_args(argv)
    if args.updates < 1 or args.check_every < 1:
        parser.error("--updates and --check-every must be ≥ 1")
    print(f"{'updates':>9} {'min eig(P)':>11} {'max eig(P)':>11} {'|P-Pᵀ|max':>10} "
          f"{'rot err deg':>11} {'trans err':>10}  ok")

    def report(e):
        print(f"{e['updates']:>9} {e['min_eigenvalue']:>11.3e} {e['max_eigenvalue']:>11.3e} "
              f"{e['asymmetry']:>10.2e} {e['rotation_error_deg']:>11.3e} "
              f"{e['translation_error']:>10.3e}  {'yes' if e['ok'] else 'NO'}", flush=True)

    result = run(args.updates, args.seed, args.check_every, report)
    print(f"{result['updates']} updates in {result['seconds']:.1f} s "
          f"({result['updates_per_second']:.0f} updates/s); "
          f"{'all checks passed' if not result['failures'] else 'CHECKS FAILED'}")
    return 1 if result["failures"] else 0


if __name__ == "__main__":
    sys.exit(main())
