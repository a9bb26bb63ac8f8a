"""The calibrator alone, fed by the paper's random small motions (docs/method.md §8).

Run: ``python diagrams/calibrator_alone.py`` — for each estimator, simulates 100 motions with the
paper's noise (coefficients of R_A σ = 0.01, t_A σ = 0.1, ‖t_X‖ ≈ 170), prints the two-motion and
final errors of X_EC, and writes calibrator_alone.dot (compact) and calibrator_alone_full.dot
(every port), and their .svg with graphviz, here.
"""
from pathlib import Path

import numpy as np
from pydrake.common import RandomGenerator
from pydrake.systems.analysis import Simulator

from handeye_drake import ManifoldFilter, PaperFilter, rotation_error_deg, translation_error_rel
from handeye_drake.apps.pictures import render_diagram
from handeye_drake.estimation.se3 import make_transform, rotation_from_rpy, vector_to_pose
from handeye_drake.simulation import build_calibrator_bench

if __name__ == "__main__":
    rng = np.random.default_rng(0)
    X_EC = make_transform(rotation_from_rpy(rng.uniform(0, 2 * np.pi, 3)),
                          rng.normal(0, 100, 3))
    # The paper's camera noise: σ = 0.01 on R_A's coefficients (σ/√2 rad per rotation axis).
    for name, estimator in (
            ("paper", PaperFilter(rotation_coefficient_sigma=0.01, translation_sigma=0.1,
                                  initial_variances=[1.0] * 12)),
            ("paper exact", PaperFilter(noise_covariance="exact", rotation_coefficient_sigma=0.01,
                                        translation_sigma=0.1, initial_variances=[1.0] * 12)),
            ("manifold", ManifoldFilter(rotation_sigma=0.01 / np.sqrt(2), translation_sigma=0.1,
                                        initial_variances=[0.01] * 3 + [100.0] * 3))):
        bench = build_calibrator_bench(X_EC, estimator, period=0.1)
        simulator = Simulator(bench.diagram)
        context = simulator.get_mutable_context()
        bench.diagram.SetRandomContext(context, RandomGenerator(0))
        simulator.AdvanceTo(0.1 * 103)
        est = bench.loggers["X_EC_estimate"].FindLog(context).data()
        two = vector_to_pose(bench.loggers["X_EC_two_motion"].FindLog(context).data()[:, -1])
        final = vector_to_pose(est[:, -1])
        print(f"{name:>11}: two-motion {rotation_error_deg(X_EC, two):.3f} deg / "
              f"{100 * translation_error_rel(X_EC, two):.2f} %  ->  after 100 motions "
              f"{rotation_error_deg(X_EC, final):.3f} deg / "
              f"{100 * translation_error_rel(X_EC, final):.2f} %")
    written = render_diagram(bench.diagram, Path(__file__).with_name("calibrator_alone"))
    print("wrote: " + ", ".join(map(str, written)))
