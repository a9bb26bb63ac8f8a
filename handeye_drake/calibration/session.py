"""A live calibration session: add samples one by one, get the estimate, its σ, the verdict so
far and the next pose to visit after each; stop when σ reaches the user's target with verdict OK.

    session = CalibrationSession(target_sigma_deg=0.1, target_sigma_mm=1.0, next_pose=planner)
    step = session.add(X_BE, X_CT)          # or session.add(X_BE, image=img, target=..., intrinsics=K)
    print(step.line()); if step.stop: result = session.result

Per sample, the on-line filter (``estimation.manifold.HandEyeTargetFilter``: an error-state EKF on
the synchronized poses, estimating the hand-eye and the fixed pose together) gives the estimate
and σ at once; the batch calibration (``api.solve``: motion-pair start, maximum likelihood,
hold-out, split-half, the usual mistakes, the verdict) runs when the filter's σ reaches the
target, every ``batch_every`` samples, and at the first samples. Only the batch decides to stop:
**stop** = the batch σ ≤ the target in rotation *and* translation, with the verdict OK. After
each batch the filter restarts from the batch estimate (with a weak prior) and replays every
sample, so it never drifts from the answer that counts.

σ: the RMS radius of the hand-eye error (√trace of the 3×3 covariance block) — rotation in deg,
translation in mm — and (``task_space.task_sigmas``) of the tool-centre point and of a point
0.5 m in front of the camera, in mm.

Frames (X_AB: pose of B in A): B robot base, E end-effector, C camera, T target. Samples are
X_BE (robot) and X_CT (target in camera). Eye-in-hand: the result is X_EC, the fixed pose X_BT;
eye-to-hand: X_BC and X_ET. Lengths m (mm where the name says), angles rad (deg where it says).

The next pose comes from an injected callable, so that this module stays free of Drake: any
``next_pose(samples_X_BE, X_H, X_F, rotation_sigma, translation_sigma) -> dict | None`` (X_H: the
hand-eye estimate, X_F the fixed pose, both None before the first estimate; the dict holds at
least ``X_BE``), e.g. ``CandidatePoses`` (the D-optimal best of a list of poses, Drake-free) or
``handeye_drake.planning.as_session_planner`` (reachable, collision-free poses from Drake's IK).

State: ``to_dict``/``save`` write JSON (settings and every sample); ``resume`` reads them back
and runs the batch on every saved sample, so a resumed session continues from the answer the
uninterrupted one would give on the same samples.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..estimation.configs import TargetFilter
from ..estimation.manifold import HandEyeTargetFilter
from ..estimation.planning import plan_next_poses
from ..estimation.se3 import inverse, rotation_angle
from ..estimation.validation import as_transform
from ..recorded.formats import MAX_TRANSLATION, pose_stream
from .api import CalibrationOptions, solve
from .inputs import Streams
from .task_space import task_sigmas

#: State file format version.
STATE_VERSION = 1
#: The state file's "format" field: what ``is_session_state`` recognises.
STATE_FORMAT = "handeye_drake session state"
#: Fewest samples before the first batch attempt.
MIN_BATCH_SAMPLES = 4
#: A sample's X_BE this close to a pose the session suggested was taken there (deg, m).
ASKED_DEG, ASKED_M = 2.0, 0.01
#: A rough hand-eye transform (a drawing) is trusted to this (deg, m) to tell a swap.
GUESS_DEG, GUESS_M = 20.0, 0.05


def sigma_floor(robot_accuracy, X_hand=None) -> tuple[float, float]:
    """The σ (deg, mm; RMS radius as the session reports it) that no number of samples goes
    below: the robot's pose error constant over the recording (``pipeline.
    robot_error_covariance``, per-axis ``robot_accuracy`` = (deg, m)) is absorbed by the
    hand-eye transform. Without ``X_hand`` (4×4) the hand-eye translation's share is left out:
    a lower bound."""
    if robot_accuracy is None:
        return 0.0, 0.0
    from .pipeline import robot_error_covariance
    cov = robot_error_covariance(np.eye(4) if X_hand is None else X_hand, robot_accuracy)
    return math.degrees(_radius(cov[:3, :3])), 1000.0 * _radius(cov[3:, 3:])


@dataclass
class SessionStep:
    """What the session says after a sample.

    Attributes:
        num_samples: samples accepted so far.
        status: "collecting" (no estimate yet), "continue" or "stop".
        source: where the estimate comes from: "filter", "batch" or "" (none yet).
        X_hand: X_EC (eye-in-hand) or X_BC (eye-to-hand), 4×4; None before an estimate.
        X_fixed: X_BT or X_ET; None before an estimate.
        rotation_sigma_deg, translation_sigma_mm: RMS radius of the hand-eye error (module
            docstring); None before an estimate.
        tcp_sigma_mm, front_sigma_mm: σ of the tool-centre point and of a point 0.5 m in front
            of the camera located through the result (mm).
        verdict: "OK", "WARN", "FAIL" from the last batch, or None before one; ``reasons`` its
            reasons (one line each).
        batch_samples: samples the last batch used (its verdict is of those).
        next_pose: the planner's dict (``X_BE``, maybe ``q``) for the pose to visit next, None
            when there is no planner, nothing left, or at stop.
        message: one line saying what to do next.
    """
    num_samples: int
    status: str
    source: str = ""
    X_hand: np.ndarray | None = None
    X_fixed: np.ndarray | None = None
    rotation_sigma_deg: float | None = None
    translation_sigma_mm: float | None = None
    tcp_sigma_mm: float | None = None
    front_sigma_mm: float | None = None
    verdict: str | None = None
    reasons: list = field(default_factory=list)
    batch_samples: int = 0
    next_pose: dict | None = None
    message: str = ""

    @property
    def stop(self) -> bool:
        return self.status == "stop"

    def line(self) -> str:
        """One line: sample count, σ, verdict, what next."""
        if self.rotation_sigma_deg is None:
            return f"[{self.num_samples:3d}] {self.status}: {self.message}"
        v = self.verdict or "—"
        return (f"[{self.num_samples:3d}] {self.status}: σ {self.rotation_sigma_deg:.3f}° / "
                f"{self.translation_sigma_mm:.2f} mm ({self.source}); tool {self.tcp_sigma_mm:.2f}"
                f" mm, 0.5 m in front {self.front_sigma_mm:.2f} mm; verdict {v}; {self.message}")

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        for k in ("X_hand", "X_fixed"):
            d[k] = None if d[k] is None else np.asarray(d[k]).tolist()
        if self.next_pose is not None:
            d["next_pose"] = {k: (np.asarray(v).tolist() if isinstance(v, np.ndarray) or (
                isinstance(v, list) and v and isinstance(v[0], np.ndarray)) else v)
                for k, v in self.next_pose.items()}
        d["stop"] = self.stop
        return d


def _radius(cov3) -> float:
    return float(math.sqrt(max(float(np.trace(cov3)), 0.0)))


class CandidatePoses:
    """A Drake-free next-pose callable: the D-optimal best (``estimation.planning``) of a fixed
    list of poses X_BE not visited yet (a candidate is visited when a sample lies within
    ``visited_deg`` and ``visited_m`` of it).

    Args:
        candidates_X_BE: (N, 4, 4) poses the robot can reach (e.g. checked on the cell).
        X_H_guess: rough X_EC (X_BC eye-to-hand), used before the first estimate.
        X_F_guess: rough X_BT (X_ET), only its position matters.
        mode: "eye_in_hand" or "eye_to_hand".
    """

    def __init__(self, candidates_X_BE, X_H_guess, X_F_guess, mode: str = "eye_in_hand",
                 visited_deg: float = 0.5, visited_m: float = 0.002):
        self.candidates = np.asarray(candidates_X_BE, float).reshape(-1, 4, 4)
        if len(self.candidates) == 0:
            raise ValueError("candidates_X_BE: the candidate set is empty")
        self.X_H = as_transform(X_H_guess, "X_H_guess")
        self.X_F = as_transform(X_F_guess, "X_F_guess")
        self.mode = mode
        self.visited_rad, self.visited_m = math.radians(visited_deg), visited_m

    def _visited(self, samples) -> np.ndarray:
        done = np.zeros(len(self.candidates), bool)
        for X in samples:
            for i, C in enumerate(self.candidates):
                if (np.linalg.norm(C[:3, 3] - X[:3, 3]) <= self.visited_m
                        and rotation_angle(C[:3, :3].T @ X[:3, :3]) <= self.visited_rad):
                    done[i] = True
        return done

    def __call__(self, samples_X_BE, X_H=None, X_F=None, rotation_sigma=0.002,
                 translation_sigma=0.001):
        free = ~self._visited(samples_X_BE)
        if not free.any():
            return None
        X_H = self.X_H if X_H is None else X_H
        X_F = self.X_F if X_F is None else X_F
        i = plan_next_poses(self.candidates, inverse(X_H), X_F, samples_X_BE, rotation_sigma,
                            translation_sigma, n=1, mode=self.mode, visibility=free,
                            exchange=False).indices[0]
        return {"X_BE": self.candidates[i], "index": int(i)}


class CalibrationSession:
    """A live calibration (module docstring).

    Args:
        target_sigma_deg, target_sigma_mm: stop when the batch σ (RMS radius of the hand-eye
            rotation, deg, and translation, mm) are at most these, with the verdict OK.
        options: ``CalibrationOptions`` of the batch fit (mode, robot accuracy, …).
        next_pose: the next-pose callable (module docstring), or None.
        camera_sigma_deg, camera_sigma_mm: the camera pose noise per axis assumed by the filter
            and the planner before the first batch (then the batch's estimate of it).
        batch_every: run the batch at least every this many samples.
        max_samples: stop suggesting poses after this many samples (None: no limit); the status
            stays "continue" with a message saying the target was not reached.
        hand_eye_guess: optional rough X_EC (X_BC eye-to-hand), 4×4: tells the robot's poses
            from the camera's when the data cannot (``roles_evidence``).

    A target below the floor the robot's accuracy puts under σ (``sigma_floor``) can never be
    reached: ValueError naming ``target_sigma_deg`` / ``target_sigma_mm`` with the floor.
    Typed samples are checked as ``calibrate`` checks pose files (swapped or inverted streams,
    quaternion order, units, clock offset): a sample file whose columns are swapped, say, never
    stops; when the data fit both readings alike the session needs ``roles_evidence``.
    """

    def __init__(self, target_sigma_deg: float = 0.1, target_sigma_mm: float = 1.0,
                 options: CalibrationOptions | None = None, next_pose=None,
                 camera_sigma_deg: float = 0.1, camera_sigma_mm: float = 1.0,
                 batch_every: int = 5, max_samples: int | None = None,
                 hand_eye_guess=None):
        for name, v in (("target_sigma_deg", target_sigma_deg),
                        ("target_sigma_mm", target_sigma_mm),
                        ("camera_sigma_deg", camera_sigma_deg),
                        ("camera_sigma_mm", camera_sigma_mm)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (
                    math.isfinite(v) and v > 0):
                raise ValueError(f"{name}: expected a finite number > 0, got {v!r}")
        if isinstance(batch_every, bool) or not isinstance(batch_every, int) or batch_every < 1:
            raise ValueError(f"batch_every: expected an integer ≥ 1, got {batch_every!r}")
        if max_samples is not None and (not isinstance(max_samples, int) or max_samples < 1):
            raise ValueError(f"max_samples: expected None or an integer ≥ 1, got {max_samples!r}")
        if options is None:
            options = CalibrationOptions()
        if not isinstance(options, CalibrationOptions):
            raise ValueError(f"options: expected a CalibrationOptions, got "
                             f"{type(options).__name__}")
        if next_pose is not None and not callable(next_pose):
            raise ValueError("next_pose: expected a callable (samples_X_BE, X_H, X_F, "
                             "rotation_sigma, translation_sigma) -> dict or None")
        self.target = (float(target_sigma_deg), float(target_sigma_mm))
        self.hand_eye_guess = None if hand_eye_guess is None else as_transform(
            hand_eye_guess, "hand_eye_guess", rigid=True)
        self.floor = sigma_floor(options.robot_accuracy, self.hand_eye_guess)
        for k, (name, unit) in enumerate((("target_sigma_deg", "°"), ("target_sigma_mm", " mm"))):
            if self.target[k] <= self.floor[k]:
                acc = (options.robot_accuracy_deg, options.robot_accuracy_mm)
                raise ValueError(
                    f"{name}: {self.target[k]:g}{unit} is below the floor {self.floor[k]:.3g}"
                    f"{unit} that the robot's accuracy ({acc[0]:g}° / {acc[1]:g} mm per axis, "
                    "constant over the recording) puts under σ — no number of samples reaches "
                    f"it; ask for more than {self.floor[k]:.3g}{unit}, or give the robot's "
                    "measured accuracy")
        self.options = options
        self.mode = options.mode
        self.next_pose = next_pose
        self.camera_sigma = (math.radians(camera_sigma_deg), camera_sigma_mm / 1000.0)
        self.batch_every = batch_every
        self.max_samples = max_samples
        self.X_BE, self.X_CT, self.stamps, self.sources = [], [], [], []
        self.skipped = []                 # (reason) of refused samples
        self.result = None                # the last batch CalibrationResult
        self._batch_n = 0
        self._batch_error = ""
        self._filter = None
        self.last = None
        self.suggested = []               # poses X_BE the session asked for
        #: The whole robot stream (``PoseStream`` with timestamps, e.g. a bag's tf) when the
        #: samples carry stamps: the batch then estimates the clock offset as ``calibrate``.
        self.robot_stream = None
        self.detections = []              # the image samples' detections (None: a typed pose)
        self._intrinsics = None

    # ------------------------------------------------------------------------------ input
    def add(self, X_BE, X_CT=None, *, image=None, target=None, intrinsics=None,
            stamp: float | None = None, evaluate: bool = True) -> SessionStep | None:
        """Adds one sample: the robot pose X_BE with the measured X_CT, or with an ``image`` of the
        ``target`` (a ``vision.targets`` spec or target) seen with ``intrinsics``
        (``vision.detection.detect_target`` measures X_CT). Returns the ``SessionStep``.

        ``evaluate=False`` only queues the sample (returns None; the filter still takes it):
        samples arriving faster than a batch fit runs are queued, then ``evaluate()`` fits once.
        A sample whose image shows no target is skipped (the step says why). ValueError naming
        the argument on bad input."""
        X_BE = as_transform(X_BE, "X_BE", rigid=True)
        source = "pose"
        if (X_CT is None) == (image is None):
            raise ValueError("X_CT / image: give the measured target pose X_CT or an image")
        if image is not None:
            if target is None or intrinsics is None:
                raise ValueError("target / intrinsics: an image sample needs the target and the "
                                 "camera intrinsics")
            from ..vision.detection import detect_target
            det = detect_target(image, target, intrinsics)
            if not det.found:
                self.skipped.append(det.reason)
                if not evaluate:
                    return None
                step = self._step()
                step.message = f"sample skipped: target not found ({det.reason}); " + step.message
                self.last = step
                return step
            X_CT, source = det.X_CT, "image"
            self._intrinsics = intrinsics
        X_CT = as_transform(X_CT, "X_CT", rigid=True)
        for name, X in (("X_BE", X_BE), ("X_CT", X_CT)):
            d = float(np.linalg.norm(X[:3, 3]))
            if d > MAX_TRANSLATION:
                raise ValueError(f"{name}: translation of length {d:g} exceeds "
                                 f"{MAX_TRANSLATION:g}: poses are expected in metres — are "
                                 "these millimetres?")
        self.X_BE.append(X_BE)
        self.X_CT.append(X_CT)
        self.stamps.append(None if stamp is None else float(stamp))
        self.sources.append(source)
        self.detections.append(det if source == "image" else None)
        self._update_filter(X_BE, X_CT)
        return self.evaluate() if evaluate else None

    def evaluate(self) -> SessionStep:
        """The ``SessionStep`` on every sample added so far (a batch fit when one is due)."""
        self.last = self._step()
        return self.last

    # ---------------------------------------------------------------------------- filters
    def _filter_sample(self, X_BE, X_CT):
        # Eye-to-hand X_CT = X_CB X_BE X_ET is eye-in-hand's X_CT = X_CE inv(X_BE) X_BT with
        # inv(X_BE) for X_BE: the filter then estimates X_CB and X_ET.
        return (X_BE if self.mode == "eye_in_hand" else inverse(X_BE)), X_CT

    def _new_filter(self, X_hand, sr, st):
        cfg = TargetFilter(rotation_sigma=sr, translation_sigma=st,
                           initial_variances=[math.radians(1.0) ** 2] * 3 + [0.01 ** 2] * 3,
                           gate_probability=None)
        return HandEyeTargetFilter(cfg, inverse(X_hand))

    def _update_filter(self, X_BE, X_CT):
        if self._filter is None:
            return
        try:
            self._filter.update(*self._filter_sample(X_BE, X_CT))
        except ValueError:
            pass

    def _filter_estimate(self):
        f = self._filter
        cov = f.X_EC_covariance
        return f.X_EC, f.X_BT, cov

    def _run_batch(self):
        n = len(self.X_BE)
        times = None
        if all(s is not None for s in self.stamps) and np.all(np.diff(self.stamps) > 0):
            times = np.array(self.stamps)
        # Typed samples (a driver's lines) are read as calibrate reads pose files: which column
        # is the robot's, the quaternion order, the units and the clock offset are all tried
        # (``checks``); only the session's own detections have known roles.
        images_only = all(o == "image" for o in self.sources)
        robot = pose_stream(np.array(self.X_BE), times, "session robot")
        if self.robot_stream is not None and times is not None:
            robot = self.robot_stream    # every robot pose recorded: the offset is estimable
        # Images: the corner-level fit of every image, as ``calibrate`` on images.
        corners = images_only and self._intrinsics is not None and all(
            d is not None for d in self.detections)
        streams = Streams(robot=robot,
                          camera=pose_stream(np.array(self.X_CT), times, "session camera"),
                          inputs={"session": {"samples": n}}, roles_known=images_only,
                          quaternion_streams=() if images_only else ("robot", "camera"),
                          intrinsics=self._intrinsics if corners else None,
                          detections=list(self.detections) if corners else [])
        options = self.options
        if times is None and options.time_offset_s is None:
            options = dataclasses.replace(options, time_offset_s=0.0)
        tries = [options]
        if times is not None and options.time_offset_s is None and robot is not \
                self.robot_stream:
            # Stamped pairs: the driver paired them, maybe across a clock offset (a moving
            # robot): the offset is estimated, as ``calibrate --time-offset auto`` (robot
            # poses interpolated between the samples); unobservable (still poses): none.
            tries.insert(0, dataclasses.replace(options, time_offset_s="auto"))
        try:
            for k, o in enumerate(tries):
                try:
                    result = solve(streams, o)
                    break
                except ValueError:
                    if k + 1 == len(tries):
                        raise
        except ValueError as e:
            self._batch_error = " ".join(str(e).split())
            self._batch_n = n
            return
        self._settle_roles(result)
        self.result, self._batch_n, self._batch_error = result, n, ""
        # The filter's noise: the camera's (from the batch) and the robot's accuracy together.
        acc = self.options.robot_accuracy or (0.0, 0.0)
        sr = math.hypot(max(result.fit.rotation_sigma, 1e-5), math.radians(acc[0]))
        st = math.hypot(max(result.fit.translation_sigma, 1e-6), acc[1])
        self._filter = self._new_filter(result.X_hand, sr, st)
        for a, b in zip(self.X_BE, self.X_CT):
            self._update_filter(a, b)

    def roles_evidence(self, result=None) -> str:
        """What says the first pose of each sample is the robot's (X_BE), not the camera's, or
        "" when nothing does. Swapped streams fit AX = ZB exactly as well, so without this (or
        the timestamps' roughness evidence of ``checks.swap_evidence``) a swap is a tie:
        - the robot reached the poses the session asked for (most samples' X_BE within
          ``ASKED_DEG`` / ``ASKED_M`` of a suggested pose);
        - the batch's hand-eye transform agrees with the rough one given (``hand_eye_guess``,
          within ``GUESS_DEG`` / ``GUESS_M``) while the swapped reading's does not."""
        n = len(self.X_BE)
        if self.suggested and n:
            asked = sum(any(np.linalg.norm(S[:3, 3] - X[:3, 3]) <= ASKED_M and
                            rotation_angle(S[:3, :3].T @ X[:3, :3]) <= math.radians(ASKED_DEG)
                            for S in self.suggested) for X in self.X_BE)
            if asked >= max(MIN_BATCH_SAMPLES, 0.5 * n):
                return (f"the robot reached the poses the session asked for ({asked} of {n} "
                        "samples)")
        result = result or self.result
        if self.hand_eye_guess is not None and result is not None:
            # The swapped reading's hand-eye transform: eye-in-hand X_TB (X_CT X_TB X_BE =
            # X_CE), eye-to-hand X_CB (X_CT X_TE = X_CB X_BE).
            X_swap = inverse(result.X_fixed if self.mode == "eye_in_hand" else result.X_hand)
            if self._near_guess(result.X_hand) and not self._near_guess(X_swap):
                return "the hand-eye transform agrees with the rough one given"
        return ""

    def _near_guess(self, X) -> bool:
        G = self.hand_eye_guess
        return bool(np.linalg.norm(G[:3, 3] - X[:3, 3]) <= GUESS_M
                    and rotation_angle(G[:3, :3].T @ X[:3, :3]) <= math.radians(GUESS_DEG))

    def _settle_roles(self, result) -> None:
        """A swap the data cannot decide is decided by ``roles_evidence`` (then the verdict is
        recomputed with the swapped reading ruled out; without evidence its WARN stays and the
        session cannot stop)."""
        swapped = next((h for h in result.hypotheses if h.code == "swapped_streams"), None)
        if swapped is None or (swapped.evidence or {}).get("reading") is not None:
            return
        why = self.roles_evidence(result)
        if not why:
            return
        from . import checks
        swapped.evidence = dict(swapped.evidence or {}, reading="as_read", session=why)
        result.verdict = checks.verdict(result)

    def _sigmas(self, X_hand, cov):
        rot = math.degrees(_radius(cov[:3, :3]))
        tra = 1000.0 * _radius(cov[3:, 3:])
        # task_sigmas takes the robot-side poses: X_EB for eye-to-hand.
        X_R = np.linalg.inv(np.array(self.X_BE)) if self.mode == "eye_to_hand" else None
        ts = task_sigmas(self.mode, X_hand, cov, X_R)
        return rot, tra, 1000.0 * ts["tool_centre_point_m"], 1000.0 * ts["point_in_front_m"]

    def _reached(self, rot, tra) -> bool:
        return rot <= self.target[0] and tra <= self.target[1]

    def _step(self) -> SessionStep:
        n = len(self.X_BE)
        need_batch = n >= MIN_BATCH_SAMPLES and (
            self.result is None or n - self._batch_n >= self.batch_every)
        if self._filter is not None and not need_batch and n > self._batch_n:
            X_h, _, cov = self._filter_estimate()
            if self._reached(*self._sigmas(X_h, cov)[:2]):
                need_batch = True       # the filter says the target is reached: let the batch decide
        if need_batch and n > self._batch_n:
            self._run_batch()
        step = SessionStep(n, "collecting")
        if self._filter is not None and self.result is not None:
            if self._batch_n == n:
                X_h, X_f, cov = self.result.X_hand, self.result.X_fixed, self.result.covariance
                step.source = "batch"
            else:
                X_h, X_f, cov = self._filter_estimate()
                step.source = "filter"
            step.X_hand, step.X_fixed = X_h, X_f
            (step.rotation_sigma_deg, step.translation_sigma_mm, step.tcp_sigma_mm,
             step.front_sigma_mm) = self._sigmas(X_h, cov)
            step.verdict = self.result.verdict.status
            step.reasons = [r.message for r in self.result.verdict.reasons]
            step.batch_samples = self._batch_n
            step.status = "continue"
            if (step.source == "batch" and step.verdict == "OK"
                    and self._reached(step.rotation_sigma_deg, step.translation_sigma_mm)):
                step.status = "stop"
                step.message = (f"σ at or below the target {self.target[0]:g}° / "
                                f"{self.target[1]:g} mm with verdict OK: calibrated")
                return step
        if self.max_samples is not None and n >= self.max_samples:
            step.message = (f"{n} samples, the most allowed: the σ target "
                            f"{self.target[0]:g}° / {self.target[1]:g} mm was not reached")
            return step
        sr, st = self.camera_sigma
        if self.result is not None:
            sr = max(self.result.fit.rotation_sigma, 1e-5)
            st = max(self.result.fit.translation_sigma, 1e-6)
        if self.next_pose is not None:
            step.next_pose = self.next_pose(list(self.X_BE), step.X_hand, step.X_fixed, sr, st)
            self._asked(step.next_pose)
        if step.status == "collecting":
            why = f" ({self._batch_error})" if self._batch_error else ""
            step.message = f"not determined yet{why}"
        elif step.verdict != "OK":
            step.message = step.reasons[0] if step.reasons else f"verdict {step.verdict}"
        else:
            step.message = (f"target {self.target[0]:g}° / {self.target[1]:g} mm not reached "
                            "yet")
        if step.next_pose is not None:
            step.message += "; move to the next pose"
        elif self.next_pose is not None:
            step.message += "; the planner has no pose left"
        else:
            step.message += "; record a new pose (rotate ≥ 20° about a new axis)"
        return step

    def _asked(self, pose):
        if pose is not None and pose.get("X_BE") is not None:
            self.suggested.append(np.asarray(pose["X_BE"], float))

    def ask_pose(self):
        """The planner's next pose now (None without a planner or none left), remembered as
        asked for: the first pose, or another after a view that gave no sample."""
        if self.next_pose is None:
            return None
        last = self.last
        pose = self.next_pose(list(self.X_BE), None if last is None else last.X_hand,
                              None if last is None else last.X_fixed)
        self._asked(pose)
        return pose

    def finish(self):
        """The batch result on every sample (runs the batch if the last one is older)."""
        if len(self.X_BE) > self._batch_n:
            self._run_batch()
        if self.result is None:
            raise ValueError("session: no calibration yet" + (
                f" ({self._batch_error})" if self._batch_error else ""))
        return self.result

    # ------------------------------------------------------------------------------ state
    def to_dict(self) -> dict:
        return {"format": STATE_FORMAT, "version": STATE_VERSION, "target_sigma_deg": self.target[0],
                "target_sigma_mm": self.target[1],
                "options": dataclasses.asdict(self.options),
                "camera_sigma_deg": math.degrees(self.camera_sigma[0]),
                "camera_sigma_mm": 1000.0 * self.camera_sigma[1],
                "batch_every": self.batch_every, "max_samples": self.max_samples,
                "hand_eye_guess": None if self.hand_eye_guess is None else
                self.hand_eye_guess.tolist(),
                "suggested": [X.tolist() for X in self.suggested],
                "samples": [{"X_BE": a.tolist(), "X_CT": b.tolist(), "stamp": s, "source": o}
                            for a, b, s, o in zip(self.X_BE, self.X_CT, self.stamps,
                                                  self.sources)],
                "skipped": self.skipped,
                "last": None if self.last is None else self.last.to_dict()}

    def save(self, path) -> None:
        """Writes the state as JSON (atomically: a crash leaves the previous file)."""
        p = Path(path)
        if p.is_dir():
            raise ValueError(f"state: {str(p)!r} is a directory, not a file")
        tmp = p.with_name(p.name + ".tmp")
        tmp.write_text(json.dumps(self.to_dict(), indent=1) + "\n")
        tmp.replace(p)

    @classmethod
    def resume(cls, path, next_pose=None) -> "CalibrationSession":
        """The session saved at ``path``, its samples replayed (the planner is given again)."""
        p = Path(path)
        if not p.is_file():
            raise ValueError(f"state: file not found: {str(p)!r}")
        try:
            d = json.loads(p.read_text())
            if d.get("version") != STATE_VERSION:
                raise ValueError(f"version {d.get('version')!r}, expected {STATE_VERSION}")
            s = cls(d["target_sigma_deg"], d["target_sigma_mm"],
                    CalibrationOptions(**d["options"]), next_pose, d["camera_sigma_deg"],
                    d["camera_sigma_mm"], d["batch_every"], d["max_samples"],
                    d.get("hand_eye_guess"))
            samples = d["samples"]
            s.suggested = [np.asarray(X, float) for X in d.get("suggested", [])]
        except (KeyError, TypeError, json.JSONDecodeError, ValueError) as e:
            raise ValueError(f"state: {p.name} is not a session state ({e})") from None
        s.skipped = list(d.get("skipped", []))
        for k in samples:
            s._append(k)
        if samples:
            s._run_batch() if len(samples) >= MIN_BATCH_SAMPLES else None
            s.last = s._step()
        return s

    def _append(self, k):
        X_BE = as_transform(k["X_BE"], "X_BE", rigid=True)
        X_CT = as_transform(k["X_CT"], "X_CT", rigid=True)
        self.X_BE.append(X_BE)
        self.X_CT.append(X_CT)
        self.stamps.append(k.get("stamp"))
        self.sources.append(k.get("source", "pose"))
        self.detections.append(None)
        self._update_filter(X_BE, X_CT)


def is_session_state(path) -> bool:
    """True when ``path`` is a file a session saved (JSON with ``STATE_FORMAT``); False for
    anything else (a sample recording, a user's file, a directory). Reads at most 64 MiB."""
    p = Path(path)
    if not p.is_file():
        return False
    try:
        if p.stat().st_size > 64 << 20:
            return False
        d = json.loads(p.read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        return False
    # (States written before the "format" field: version 1 with the session's own keys.)
    return isinstance(d, dict) and (d.get("format") == STATE_FORMAT or (
        "format" not in d and d.get("version") == 1 and {"target_sigma_deg", "options",
                                                          "samples"} <= d.keys()))


__all__ = ["CalibrationSession", "CandidatePoses", "MIN_BATCH_SAMPLES", "SessionStep",
           "is_session_state", "sigma_floor"]
