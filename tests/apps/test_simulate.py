"""``handeye-drake simulate`` and ``scenario`` (``apps.simulate``): what a user sees."""

import json

import numpy as np
import pytest

from handeye_drake.apps.cli import main
from handeye_drake.scenario import load_scenario
from handeye_drake.simulation import run_scenario


def test_simulate_writes_its_artefacts_and_a_quiet_summary(tmp_path, capfd):
    out = tmp_path / "out"
    assert main(["simulate", "--out", str(out), "--no-progress"]) == 0
    stdout, stderr = capfd.readouterr()
    names = {p.name for p in out.iterdir()} - {"diagram.svg", "diagram_full.svg"}  # graphviz
    assert names == {".handeye-drake-output.json", "diagram.dot", "diagram_full.dot",
                     "feature_error.png",
                     "handeye_error.png", "image_trajectories.png", "replay.html",
                     "summary.json"}
    summary = json.loads((out / "summary.json").read_text())
    assert summary["two_motion_solution_found"] and summary["estimator"] == "TargetFilter"
    # The estimates themselves: the final X_EC with its covariance, the two-motion X_EC; their
    # errors against the truth are the ones the summary states.
    from handeye_drake import rotation_error_deg
    X, X0, X_true = (np.array(summary[k]) for k in ("final_X_EC", "two_motion_X_EC",
                                                    "true_X_EC"))
    assert abs(rotation_error_deg(X_true, X) - summary["final_rotation_error_deg"]) < 1e-6
    assert abs(rotation_error_deg(X_true, X0) - summary["two_motion_rotation_error_deg"]) < 1e-6
    C = np.array(summary["final_X_EC_covariance"])
    assert C.shape == (6, 6) and np.allclose(C, C.T) and np.all(np.linalg.eigvalsh(C) > 0)
    np.testing.assert_allclose(np.degrees(np.sqrt(np.diag(C)[:3])),
                               summary["final_X_EC_rotation_std_deg"], rtol=1e-9)
    np.testing.assert_allclose(np.sqrt(np.diag(C)[3:]), summary["final_X_EC_translation_std"],
                               rtol=1e-9)
    assert "two-motion estimate (daniilidis): rotation" in stdout
    assert "final on-line estimate" in stdout and "WARNING" not in stdout
    # A batch run has no live Meshcat server to advertise.
    assert "listening for connections" not in stdout + stderr
    # Re-running into its own output works; a second command's output directory is refused.
    assert main(["simulate", "--duration", "5", "--out", str(out), "--no-progress",
                 "--no-meshcat"]) == 0
    assert not (out / "replay.html").exists()  # the earlier run's file, not written again
    # 5 s leave 1 s of servoing: the run says the servo has not converged.
    assert "WARNING: the servo did not converge" in capfd.readouterr().out


@pytest.mark.parametrize("args, message", [
    (["--out", "{file}"], "--out .*exists and is not a directory"),
    (["--meshcat-html", "{missing}/replay.html"], "--meshcat-html .*does not exist"),
    (["--scenario", "{missing}/s.yaml"], "no such file"),
    (["--duration", "1e9"], "duration: 1e\\+09 s is longer than"),
    (["--seed", "-1"], "seed: expected an integer in"),
])
def test_bad_output_paths_and_values_fail_before_simulating(tmp_path, capsys, args, message):
    (tmp_path / "file").write_text("")
    args = [a.format(file=tmp_path / "file", missing=tmp_path / "missing") for a in args]
    assert main(["simulate", "--no-progress"] + args
                + ([] if "--out" in args else ["--out", str(tmp_path / "o")])) == 2
    err = capsys.readouterr().err
    assert err.startswith("handeye-drake: error: ") and err.count("\n") == 1
    import re
    assert re.search(message, err), err
    assert not (tmp_path / "o" / "summary.json").exists()


def test_strict_fails_when_the_two_motion_start_failed(tmp_path, capsys):
    scenario = tmp_path / "s.yaml"
    scenario.write_text("servo:\n  self_calibration:\n    - {axis_C: [1, 0, 0], angle_deg: 0.0}\n"
                        "    - {axis_C: [0, 1, 0], angle_deg: 0.0}\nduration: 5.0\n")
    assert main(["simulate", "--scenario", str(scenario), "--out", str(tmp_path / "a"),
                 "--no-progress", "--no-meshcat"]) == 0
    out = capsys.readouterr().out
    assert "two-motion estimate (daniilidis): FAILED" in out
    assert "WARNING: the two-motion solution failed" in out
    assert json.loads((tmp_path / "a" / "summary.json").read_text())[
        "two_motion_rotation_error_deg"] is None
    assert main(["simulate", "--scenario", str(scenario), "--out", str(tmp_path / "b"),
                 "--no-progress", "--no-meshcat", "--strict"]) == 1


def test_an_interrupted_run_keeps_what_it_simulated():
    s = load_scenario()

    def stop_at_two_seconds(t):
        if t > 2.0:
            raise KeyboardInterrupt

    r = run_scenario(s, progress=stop_at_two_seconds)
    assert r.interrupted and 2.0 < r.sim_time < 2.5
    assert len(r.times) > 50 and np.all(np.isfinite(r.X_EC_estimates))
    assert r.summary()["interrupted"]


def test_scenario_command_prints_a_loadable_template(capsys):
    assert main(["scenario"]) == 0
    text = capsys.readouterr().out
    assert "calibrator:" in text and "sensor:" in text
    assert load_scenario(text=text).seed == 0


def test_diagram_pictures_do_not_depend_on_drakes_edge_order():
    from handeye_drake.apps.pictures import _stable_dot
    a = "digraph {\nnode1\ns2:y0:e -> s3:u0:w\ns1:y1:e -> s2:u0:w\nnode2\ns1:y0:e -> s4:u0:w\n}"
    b = "digraph {\nnode1\ns1:y0:e -> s4:u0:w\ns2:y0:e -> s3:u0:w\nnode2\ns1:y1:e -> s2:u0:w\n}"
    assert _stable_dot(a) == _stable_dot(b)
    assert _stable_dot(a).split("\n")[:4] == ["digraph {", "node1", "s1:y0:e -> s4:u0:w",
                                               "s1:y1:e -> s2:u0:w"]
