"""handeye-drake sweep: the grid, Dask against serial, resume, bad --set options."""

import contextlib
import csv
import io

import pytest

from handeye_drake.apps.cli import main
from handeye_drake.apps.executors import make_executor
from handeye_drake.apps.sweep import (
    RESULTS,
    SweepSpec,
    parse_path,
    run_sweep,
    split_values,
)

SETS = ["calibrator.estimator=!PaperFilter,!TargetFilter", "duration=5"]
VARYING = ("wall_time_s", "worker")  # the only columns that differ between runs


def read_rows(out):
    with open(out / RESULTS, newline="") as f:
        rows = list(csv.DictReader(f))
    return {(r["calibrator.estimator"], r["seed"]): {k: v for k, v in r.items()
                                                     if k not in VARYING} for r in rows}


@pytest.fixture(scope="module")
def spec():
    return SweepSpec.from_options(None, SETS, "0:2")


@pytest.fixture(scope="module")
def serial(spec, tmp_path_factory):
    out = tmp_path_factory.mktemp("serial")
    report = run_sweep(spec, out, executor=None, progress=False)
    return out, report


def test_grid_and_serial_rows(spec, serial):
    out, report = serial
    assert [s for s in spec.settings()] == [
        [("calibrator.estimator", "!PaperFilter"), ("duration", "5")],
        [("calibrator.estimator", "!TargetFilter"), ("duration", "5")]]
    assert report.ran == 4 and report.failed == 0 and report.done_before == 0
    rows = read_rows(out)
    assert sorted(rows) == [("!PaperFilter", "0"), ("!PaperFilter", "1"),
                            ("!TargetFilter", "0"), ("!TargetFilter", "1")]
    for (estimator, seed), row in rows.items():
        assert row["status"] == "ok" and row["simulated_time_s"] == "5.0"
        # The same seed gives the same two-motion start whatever the estimator.
        assert row["two_motion_rotation_error_deg"] == \
            rows[("!TargetFilter", seed)]["two_motion_rotation_error_deg"]
    # AX = ZB on raw poses beats the paper's filter in translation on every seed.
    for seed in ("0", "1"):
        assert float(rows[("!TargetFilter", seed)]["final_translation_error_pct"]) < 0.2 * float(
            rows[("!PaperFilter", seed)]["final_translation_error_pct"])
    assert (out / "errors.png").stat().st_size > 10_000 and (out / "summary.md").is_file()


def test_local_cluster_equals_serial_row_by_row(spec, serial, tmp_path):
    with make_executor(dask_local=2) as (executor, where):
        assert "LocalCluster" in where
        report = run_sweep(spec, tmp_path, executor=executor, progress=False)
    assert report.ran == 4 and report.failed == 0
    workers = {r["worker"] for r in report.rows}
    assert len(workers) == 2  # both Dask worker processes ran some
    assert read_rows(tmp_path) == read_rows(serial[0])


def test_resume_runs_only_the_missing_runs(spec, serial, tmp_path):
    full = (serial[0] / RESULTS).read_text().splitlines(keepends=True)
    # A sweep killed while writing its third row: header, two rows and a torn line.
    (tmp_path / RESULTS).write_text("".join(full[:3]) + full[3][:25])
    (tmp_path / "sweep.json").write_text((serial[0] / "sweep.json").read_text())
    (tmp_path / ".handeye-drake-output.json").write_text(
        (serial[0] / ".handeye-drake-output.json").read_text())
    with pytest.raises(ValueError, match="pass --resume"):
        run_sweep(spec, tmp_path, progress=False)
    report = run_sweep(spec, tmp_path, resume=True, progress=False, plots=False)
    assert report.done_before == 2 and report.ran == 2
    assert read_rows(tmp_path) == read_rows(serial[0])
    again = run_sweep(spec, tmp_path, resume=True, progress=False, plots=False)
    assert again.ran == 0 and len(read_rows(tmp_path)) == 4
    other = SweepSpec.from_options(None, ["duration=5"], "0:2")
    with pytest.raises(ValueError, match="holds another sweep"):
        run_sweep(other, tmp_path, resume=True, progress=False)


def test_a_failing_run_is_recorded_and_the_sweep_goes_on(tmp_path):
    # The target far away: the scenario loads, but the run fails when its diagram is built.
    spec = SweepSpec.from_options(None, ["target.X_WT.translation=[-0.47, -0.10, 0.0],"
                                         "[5.0, 5.0, 0.0]", "duration=0.2"], "0")
    report = run_sweep(spec, tmp_path, progress=False, plots=False)
    assert report.ran == 2 and report.failed == 1
    status = {r["target.X_WT.translation"]: r["status"] for r in report.rows}
    assert status["[-0.47, -0.10, 0.0]"] == "ok"
    assert status["[5.0, 5.0, 0.0]"].startswith(
        "error: ValueError: arm.q0_deg / target.X_WT: at the start pose the target points")


@pytest.mark.parametrize("option, message", [
    ("calibrator.estimatr=!PaperFilter",
     "calibrator.estimatr: unknown field; did you mean 'estimator'"),
    ("servo.self_calibration[5].angle_deg=10", "index 5 out of range"),
    ("servo.self_calibration[0].angle_dg=10",
     r"servo.self_calibration\[0\].angle_dg: unknown field; did you mean 'angle_deg'"),
    ("camera.model.pose_noise.rotation_sigma=abc",
     "camera.model.pose_noise.rotation_sigma: expected a number, got 'abc'"),
    ("calibrator.estimator=!Nope", "unknown type tag !Nope"),
    ("camera.model.pixel_sigma=-1", "camera.model.pixel_sigma: must be finite and ≥ 0"),
    ("seed=1,2", "seeds are swept with --seeds"),
    ("duration", "expected PATH=VALUE"),
    ("servo..gain=1", "is not a field name"),
])
def test_bad_set_options_are_one_line_errors(option, message, tmp_path):
    with pytest.raises(ValueError, match=message):
        SweepSpec.from_options(None, [option], "0:2")
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main(["sweep", "--seeds", "0:2", "--set", option, "--out", str(tmp_path / "o"),
                     "--no-progress"])
    assert code == 2 and err.getvalue().count("\n") == 1
    assert err.getvalue().startswith("handeye-drake: error: --set")
    assert not (tmp_path / "o").exists()  # refused before anything was written


def test_paths_values_and_seeds():
    assert parse_path("servo.self_calibration[0].angle_deg") == [
        "servo", "self_calibration", 0, "angle_deg"]
    assert split_values("[1, 0, 0],[0, 1, 0]") == ["[1, 0, 0]", "[0, 1, 0]"]
    assert split_values("!ManifoldFilter {start: ml, iterations: 2},!PaperFilter") == [
        "!ManifoldFilter {start: ml, iterations: 2}", "!PaperFilter"]
    spec = SweepSpec.from_options(None, [
        "servo.self_calibration[0].angle_deg=10,15",
        "calibrator.estimator=!ManifoldFilter {start: ml, iterations: 2}"], "3,7")
    assert spec.seeds == [3, 7] and len(spec.tasks()) == 4
    from handeye_drake.apps.sweep import build_scenario
    s = build_scenario(spec.base_text, spec.settings()[1], 7)
    assert s.seed == 7 and s.servo.self_calibration[0].angle_deg == 15.0
    assert type(s.calibrator.estimator).__name__ == "ManifoldFilter"
    assert s.calibrator.estimator.start == "ml" and s.calibrator.estimator.iterations == 2
    for bad in ("", "5:2", "a", "1,1"):
        with pytest.raises(ValueError, match="--seeds"):
            SweepSpec.from_options(None, [], bad)


@pytest.mark.parametrize("argv, message", [
    (["--seeds", "0:1000000000000"], "--seeds 0:1000000000000: 1000000000000 seeds; a sweep "
     "takes at most 100000 runs (about a second each)"),
    (["--seeds", "7:100008"], "--seeds 7:100008: 100001 seeds; a sweep takes at most 100000 runs"),
    (["--seeds", "0:1001", "--set", "duration=1,2,3,4,5,6,7,8,9,10", "--set",
      "camera.sensor.fps=1,2,3,4,5,6,7,8,9,10"],
     "--set, --seeds: 100100 runs (10 × 10 settings × 1001 seeds); a sweep takes at most 100000"),
])
def test_a_sweep_too_large_is_refused_at_once_in_one_line(argv, message, tmp_path, capsys):
    import tracemalloc
    tracemalloc.start()
    try:
        code = main(["sweep", *argv, "--out", str(tmp_path / "out")])
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert message in err and peak < 50e6 and not (tmp_path / "out").exists()
