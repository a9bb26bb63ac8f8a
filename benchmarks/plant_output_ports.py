"""The closed loop against the arm alone with the plant's output ports sampled and live, paired.

    OPENBLAS_NUM_THREADS=1 python benchmarks/plant_output_ports.py [--repeats N]

Drake's discrete ``MultibodyPlant`` samples its output ports by default: each step is then an
unrestricted update, after which the simulator asks every system for its witness functions again
(through pybind11 for each Python system). The default plant config here reports them live
(``systems.arm.DEFAULT_PLANT_CONFIG``). This script times, in one process and interleaved
(A B C D, D C B A, ...: drifts of this machine's speed hit all four alike), the default closed
loop (``run_scenario``) and ``benchmark speed``'s reference (the same arm and plant config driven
by Drake's C++ ``DifferentialInverseKinematicsIntegrator``, ``apps.speed.arm_reference_diagram``)
with ``use_sampled_output_ports`` True and False, garbage collection off while timing as in
``benchmark speed``. It prints each median and, per mode, the loop / reference ratio of the
medians and the median and range of the ratios of the runs paired in time.
"""

from __future__ import annotations

import argparse
import gc
import statistics


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=9)
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error(f"--repeats: must be ≥ 1, got {args.repeats}")

    from handeye_drake.apps.speed import (
        arm_reference_diagram,
        load_average,
        pin_blas_threads,
        simulate_reference,
    )
    from handeye_drake.scenario import load_scenario
    from handeye_drake.simulation import run_scenario

    print(f"BLAS: {pin_blas_threads()}; {load_average()}")

    def reference(scenario):
        diagram, ik, _, q0 = arm_reference_diagram(scenario)
        return lambda: simulate_reference(scenario, diagram, ik, q0)[0]

    runners = {}
    for sampled in (True, False):
        scenario = load_scenario()
        scenario.plant_config.use_sampled_output_ports = sampled
        run_scenario(scenario)  # warm: compiled kernels loaded, caches filled
        runners[("loop", sampled)] = lambda s=scenario: run_scenario(s).wall_time
        runners[("reference", sampled)] = reference(scenario)
    times = {key: [] for key in runners}
    order = list(runners)
    for r in range(args.repeats):
        for key in (order if r % 2 == 0 else order[::-1]):
            gc.collect()
            gc.disable()
            try:
                times[key].append(runners[key]())
            finally:
                gc.enable()
    for sampled in (True, False):
        mode = "sampled (Drake's default)" if sampled else "live (ours)"
        loop, ref = times[("loop", sampled)], times[("reference", sampled)]
        pairs = [a / b for a, b in zip(loop, ref)]
        print(f"{mode:26s} loop {statistics.median(loop):.3f} s, reference "
              f"{statistics.median(ref):.3f} s: ratio of medians "
              f"{statistics.median(loop) / statistics.median(ref):.2f}×, paired ratios median "
              f"{statistics.median(pairs):.2f}× (range {min(pairs):.2f}–{max(pairs):.2f}×)")
    print(load_average())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
