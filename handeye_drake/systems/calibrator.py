"""The on-line hand-eye calibrator as a discrete Drake system.

Life cycle, driven by the ``phase`` input (the servo controller's ``phase`` output in the
closed loop; in your own diagram, any source of the motion index — a ``ConstantVectorSource``,
a ``TrajectorySource``, your sequencer):

1. While phase < M (the M self-calibration motions run), it records the synchronized robot and
   camera poses at every phase boundary ("key frames") and, for the replay, every sample.
2. When phase reaches M (servoing starts) it solves the M motion pairs between key frames with a
   classical solver (Daniilidis by default, as the paper) and starts the on-line estimator there
   (``estimation.startup.start_estimator``: the estimator's settings decide whether the recorded
   samples are replayed, or an ML start-up is used).
3. Then, at every sample, it calls the estimator's ``update``: the estimator is any
   ``estimation.estimator.OnlineEstimator``, selected by its settings type
   (``configs.TargetFilter`` — AX = ZB on the raw poses, the default —, ``ManifoldFilter``,
   ``PaperFilter``). Its whole state is this system's discrete state (``to_vector`` /
   ``from_vector``), so a step of this system is exactly a step of the estimator class.

The estimate outputs are wired back to the controller's interaction matrix: that is the feedback
of the design.

Timing: both pose inputs must be sampled at the same instants (the camera trigger). In the
closed-loop diagram the robot pose goes through a ``ZeroOrderHold`` clocked with the camera, and
this system updates ``offset`` after the trigger (half a period by default; the closed loop uses
the arm driver's step, a time the simulator steps to anyway), when both hold that trigger's
sample.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.systems.framework import LeafSystem

from ..estimation import defaults, kernels
from ..estimation.se3 import inverse, pose_to_vector, vector_to_pose
from ..estimation.solvers import METHODS as SOLVER_METHODS
from ..estimation.startup import estimator_type, start_estimator, two_motion_estimate
from ..estimation.validation import as_transform, check_positive

#: Values of the ``status`` output's first entry.
STATUS_COLLECTING = 0.0   # self-calibration motions in progress, output = initial guess
STATUS_FILTERING = 1.0    # two-motion solution found, on-line estimator running
STATUS_INIT_FAILED = 2.0  # filtering from the guess (motions rejected, or M = 0)

_SAMPLE = 24  # a synchronized sample: X_BE and X_CT as pose vectors


#: Share of rejected measurements above which the calibrator's σ outputs are nan (refused).
REFUSED_SIGMA_REJECTIONS = 0.25


class HandEyeCalibrator(LeafSystem):
    """Discrete on-line hand-eye calibrator.

    Input ports:
        X_BE (12): robot pose, end-effector E in robot base B, [vec_row(R); p (m)], sampled at the
            camera trigger.
        X_CT_measured (12): measured target pose in the camera (may be non-orthonormal under the
            paper's noise model), same instants.
        phase (1): the controller's phase; values < num_self_calibration_motions mean motion k is
            running, larger values mean servoing.
        X_CT_valid (1, optional): 1.0 when X_CT_measured holds a measurement of this instant
            (e.g. a detector's ``found``); a 0.0 sample is skipped. Unconnected: always valid.
        X_CT_covariance (36, optional): row-major 6×6 covariance of [δθ (rad); δt (m)] of
            X_CT_measured, used by estimators whose settings ask for it.

    Phases (what drives ``phase`` and what the calibrator needs before it estimates):
        With M = ``num_self_calibration_motions`` ≥ 2, the robot performs M rotations (the
        self-calibration motions: ≥ 5° each, about non-parallel axes) while ``phase`` reads
        0, 1, …, M−1, then ``phase`` ≥ M (servoing, or any further motion). The first sample
        and the first sample of each phase ≥ k are the key frames; when the sample with
        phase ≥ M arrives, the M motions between the M+1 key frames give the classical
        two-motion solution and the estimator starts there (``status`` 1); if the motions do
        not determine X (too small, parallel axes), it starts from the initial guess with a
        wider covariance (``status`` 2). Setting ``phase`` = M from the first sample gives three
        consecutive key frames: motions far too small — use M = 0 instead.
        With M = 0 there are no self-calibration motions and ``phase`` may stay unconnected:
        the estimator starts from ``X_EC_initial_guess`` at the first sample (a guess within a
        few degrees and centimetres; ``status`` 2 says it started from a guess) and refines it
        from every sample after.

    Output ports:
        X_CE_estimate (12): the paper's X (E in C), an exact rigid transform.
        X_EC_estimate (12): the camera on the hand, inv(X_CE_estimate).
        X_EC_two_motion (12): the classical two-motion solution (the initial guess until known).
        X_EC_std (6): standard deviations of X_EC: rotation about E's axes (deg), translation
            (m, in E), from the estimator's covariance scaled by the camera noise estimated
            on-line (``_noise_scale``: the fused measurements' mean NIS over its expectation,
            ≥ 1, after ``defaults.NIS_MIN_UPDATES`` of them), so a σ setting that understates
            the camera's noise does not give a σ smaller than the error; nan (refused: no
            basis) while the gate rejects more than ``REFUSED_SIGMA_REJECTIONS`` of the
            measurements (a noise setting far below the camera's).
        X_EC_covariance (36): row-major 6×6 covariance of X_EC's error [δθ (rad); δt (m)],
            scaled alike.
        status (4): [STATUS_*, accepted updates, rejected measurements, last NIS (−1 if none)].

    Discrete state: the estimator's vector, the mode, the key frames, the buffer of
    self-calibration samples, and one group per output (computed when the estimate changes, so
    reading an output runs no Python).
    """

    def __init__(self, period: float, X_CE_initial_guess=None, estimator=None,
                 num_self_calibration_motions: int = 2, init_method: str = "daniilidis",
                 max_self_calibration_samples: int = 0, offset: float | None = None, *,
                 X_EC_initial_guess=None):
        """
        Args:
            period: sample period (s), the camera's.
            X_CE_initial_guess, X_EC_initial_guess: the initial guess, as the paper's X (E in C)
                or as the camera on the hand (the outputs' convention) — exactly one (4×4
                rigid); used until the two-motion solution exists, or as the start with M = 0.
            estimator: the estimator's settings (``estimation.configs``). Their noise σ must be
                set: ``TargetFilter(rotation_sigma=…, translation_sigma=…)`` (rad, m: the camera
                pose's noise); a scenario fills them from its camera model, nothing else does.
            num_self_calibration_motions: M ≥ 2, or 0 (no self-calibration motions: see
                "Phases").
            init_method: classical solver of the M motions (see ``solve_ax_xb``).
            max_self_calibration_samples: size of the buffer of self-calibration samples
                replayed (or used by an ML start-up) when the estimator starts.
            offset: update offset after the camera trigger (default: half a period).
        """
        super().__init__()
        self._period = check_positive(period, "period")
        self._offset = 0.5 * self._period if offset is None else check_positive(
            offset, "offset", allow_zero=True)
        if (X_CE_initial_guess is None) == (X_EC_initial_guess is None):
            raise ValueError("initial guess: give exactly one of X_EC_initial_guess (camera on "
                             "the hand, the outputs' convention) and X_CE_initial_guess (its "
                             "inverse, the paper's X)")
        X0 = as_transform(X_CE_initial_guess, "X_CE_initial_guess") \
            if X_CE_initial_guess is not None else \
            inverse(as_transform(X_EC_initial_guess, "X_EC_initial_guess"))
        if estimator is None:
            raise ValueError("estimator: the estimator's settings are needed, e.g. "
                             "TargetFilter(rotation_sigma=0.002, translation_sigma=0.0005) "
                             "(the camera pose's noise, rad and m)")
        M = num_self_calibration_motions
        if isinstance(M, bool) or not isinstance(M, (int, np.integer)) or M == 1 or M < 0:
            raise ValueError("num_self_calibration_motions: needs an integer ≥ 2 (two motions "
                             f"with non-parallel axes), or 0 (start from the guess), got {M!r}")
        if init_method not in SOLVER_METHODS:
            raise ValueError(f"init_method: expected one of {SOLVER_METHODS}, got {init_method!r}")
        cap = max_self_calibration_samples
        if isinstance(cap, bool) or not isinstance(cap, (int, np.integer)) or cap < 0:
            raise ValueError("max_self_calibration_samples: needs an integer ≥ 0, got "
                             f"{cap!r}")
        self._kind = estimator_type(estimator)
        self._config = estimator.validated()
        # The estimator's compiled per-sample step on its state vector, where it has one.
        self._vector_step = (self._kind.vector_step(self._config)
                             if hasattr(self._kind, "vector_step") else None)
        self._M = int(M)
        self._init_method = init_method
        self._capacity = int(cap)
        self._X_CE_guess = X0

        self._X_BE_port = self.DeclareVectorInputPort("X_BE", 12)
        self._X_CT_port = self.DeclareVectorInputPort("X_CT_measured", 12)
        self._phase_port = self.DeclareVectorInputPort("phase", 1)
        self._valid_port = self.DeclareVectorInputPort("X_CT_valid", 1)
        self._covariance_in_port = self.DeclareVectorInputPort("X_CT_covariance", 36)

        initial = self._kind(self._config, X0)
        self._memo = (None, None)  # (state bytes, estimator): see _Estimator
        self._estimator_index = self.DeclareDiscreteState(initial.to_vector())
        self._mode_index = self.DeclareDiscreteState([STATUS_COLLECTING])
        self._keys_index = self.DeclareDiscreteState((self._M + 1) * _SAMPLE)
        self._num_keys_index = self.DeclareDiscreteState(1)
        self._buffer_index = self.DeclareDiscreteState(max(1, self._capacity * _SAMPLE))
        self._num_buffered_index = self.DeclareDiscreteState(1)
        # The outputs are computed when the estimate changes and held as discrete state: reading
        # them (the servo, loggers) costs no Python.
        values = self._OutputValues(initial, STATUS_COLLECTING)
        self._output_indices = {name: self.DeclareDiscreteState(v) for name, v in values.items()}
        self._output_indices["X_EC_two_motion"] = self.DeclareDiscreteState(
            pose_to_vector(inverse(X0)))
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, self._offset, self._UpdateEstimate)

        self._X_CE_port, self._X_EC_port, self._std_port, self._covariance_port, \
            self._status_port, self._two_motion_port = (
                self.DeclareStateOutputPort(name, self._output_indices[name])
                for name in ("X_CE_estimate", "X_EC_estimate", "X_EC_std", "X_EC_covariance",
                             "status", "X_EC_two_motion"))

    # Ports, as members so users can wire them by handle.
    def get_X_BE_input_port(self):
        return self._X_BE_port

    def get_X_CT_input_port(self):
        return self._X_CT_port

    def get_phase_input_port(self):
        return self._phase_port

    def get_X_CT_valid_input_port(self):
        return self._valid_port

    def get_X_CT_covariance_input_port(self):
        return self._covariance_in_port

    def get_X_CE_output_port(self):
        return self._X_CE_port

    def get_X_EC_output_port(self):
        return self._X_EC_port

    def get_two_motion_output_port(self):
        return self._two_motion_port

    def get_X_EC_std_output_port(self):
        return self._std_port

    def get_X_EC_covariance_output_port(self):
        return self._covariance_port

    def get_status_output_port(self):
        return self._status_port

    @property
    def period(self) -> float:
        return self._period

    @property
    def estimator_config(self):
        """The (validated) settings of the estimator this system runs."""
        return self._config

    def estimator(self, context):
        """The estimator object held in ``context`` (a copy: changing it changes nothing)."""
        return self._Estimator(context)._copy()

    def SetEstimator(self, context, estimator, X_CE_two_motion=None) -> None:
        """Puts this system in ``context`` (its own context) in the filtering mode with the given
        estimator's state — e.g. to resume from an earlier calibration, skipping the
        self-calibration motions. ``estimator``: of this system's estimator type and settings
        (``estimator_config``). ``X_CE_two_motion``: what the ``X_EC_two_motion`` output reports
        (default: the estimator's current X_CE)."""
        if type(estimator) is not self._kind or estimator.config != self._config:
            raise ValueError(f"estimator: expected a {self._kind.__name__} with this system's "
                             f"settings {self._config!r}, got {type(estimator).__name__}")
        X_CE = (estimator.X_CE if X_CE_two_motion is None
                else as_transform(X_CE_two_motion, "X_CE_two_motion"))
        context.SetDiscreteState(self._estimator_index, estimator.to_vector())
        context.SetDiscreteState(self._mode_index, [STATUS_FILTERING])
        for name, v in self._OutputValues(estimator, STATUS_FILTERING).items():
            context.SetDiscreteState(self._output_indices[name], v)
        context.SetDiscreteState(self._output_indices["X_EC_two_motion"],
                                 pose_to_vector(inverse(X_CE)))

    def _Estimator(self, context):
        """The estimator of the state in ``context``, decoded once per distinct state: the
        object is shared (by the outputs' cache, by the next update) and must not be changed —
        ``_UpdateEstimate`` updates a ``_copy()``. Keyed by the state's bytes, so any context
        holding the same state gets an equal estimator (``from_vector`` is an exact inverse of
        ``to_vector``)."""
        v = context.get_discrete_state(self._estimator_index).get_value()
        key = v.tobytes()
        memo_key, memo = self._memo
        if key != memo_key:
            memo = self._kind.from_vector(self._config, v)
            self._memo = (key, memo)
        return memo

    # --------------------------------------------------------------------------- the update
    def _UpdateEstimate(self, context, discrete_state):
        if self._valid_port.HasValue(context) and self._valid_port.Eval(context)[0] < 0.5:
            return  # no measurement at this instant (e.g. the target was not detected)
        X_BE_vec = self._X_BE_port.Eval(context)
        X_CT_vec = self._X_CT_port.Eval(context)
        if not kernels.all_finite(X_BE_vec, X_CT_vec):
            raise ValueError(f"HandEyeCalibrator at t={context.get_time():.4f}: non-finite pose "
                             "on the X_BE or X_CT_measured input")
        mode = context.get_discrete_state(self._mode_index).get_value()[0]
        if mode == STATUS_COLLECTING:
            self._Collect(context, discrete_state, np.concatenate([X_BE_vec, X_CT_vec]))
            return
        covariance = None
        if self._covariance_in_port.HasValue(context):
            covariance = self._covariance_in_port.Eval(context).reshape(6, 6)
        elif self._vector_step is not None:
            # The estimator's compiled step on its state vector (no object decoded or encoded;
            # equal bit for bit to the update below), unless it leaves the sample to it.
            code, v, x_CE, x_EC, std, cov, status = self._vector_step(
                context.get_discrete_state(self._estimator_index).get_value(), X_BE_vec,
                X_CT_vec, mode)
            if code != 2:
                discrete_state.set_value(self._estimator_index, v)
                indices = self._output_indices
                scale = self._noise_scale(v)
                discrete_state.set_value(indices["X_CE_estimate"], x_CE)
                discrete_state.set_value(indices["X_EC_estimate"], x_EC)
                discrete_state.set_value(indices["X_EC_std"], std * math.sqrt(scale))
                discrete_state.set_value(indices["X_EC_covariance"], cov * scale)
                discrete_state.set_value(indices["status"], status)
                return
        X_BE, X_CT, _ = kernels.sample_poses(X_BE_vec, X_CT_vec)
        estimator = self._Estimator(context)._copy()
        if covariance is None:
            estimator._update(X_BE, X_CT)
        else:
            estimator._update(X_BE, X_CT, covariance)
        self._SetEstimatorState(discrete_state, estimator, mode)

    def _SetEstimatorState(self, discrete_state, estimator, mode) -> None:
        v = estimator.to_vector()
        discrete_state.set_value(self._estimator_index, v)
        self._memo = (v.tobytes(), estimator)  # the next step's state: no decoding then
        values = self._OutputValues(estimator, mode)
        scale = self._noise_scale(v)
        values["X_EC_std"] = values["X_EC_std"] * math.sqrt(scale)
        values["X_EC_covariance"] = values["X_EC_covariance"] * scale    # nan: refused
        for name, value in values.items():
            discrete_state.set_value(self._output_indices[name], value)

    def _noise_scale(self, v) -> float:
        """The factor (≥ 1) on the estimator's covariance that makes the fused measurements'
        mean NIS its expectation (the measurement dimension): the camera noise estimated
        on-line, once ``defaults.NIS_MIN_UPDATES`` measurements are in. The estimator's σ
        settings may understate the camera's noise (they are often guessed); its innovations
        say by how much. (Only inflates, and only beyond the 99.9 % bound of a right setting:
        a noise overstated leaves σ conservative.)"""
        # The estimators' state vectors end with ``EstimatorBase._COUNTERS``: …, nis_sum,
        # nis_count, excitation (9).
        nis_sum, nis_count = float(v[-11]), float(v[-10])
        updates, rejected = float(v[-17]), float(v[-16])
        if updates + rejected >= defaults.NIS_MIN_UPDATES and \
                rejected > REFUSED_SIGMA_REJECTIONS * (updates + rejected):
            # The gate refuses a large share of the measurements: the noise setting is far
            # from the camera's, the estimate follows only the measurements it let through,
            # and no scaling gives its σ a basis. σ = nan: refused (``status`` counts them).
            return math.nan
        if nis_count < defaults.NIS_MIN_UPDATES:
            return 1.0
        dof = self._kind._MEASUREMENT_DOF
        ratio = nis_sum / (nis_count * dof)
        # Only where the data say so (3.1 standard deviations of the mean of χ²/dof, the
        # 99.9 % one-sided bound): a right setting's σ stays as the estimator computes it.
        return ratio if ratio > 1.0 + 3.1 * math.sqrt(2.0 / (dof * nis_count)) else 1.0

    @staticmethod
    def _OutputValues(e, mode) -> dict:
        """The outputs' values for estimator ``e`` in ``mode``."""
        nis = e.last_nis if np.isfinite(e.last_nis) else -1.0
        # pose_to_vector of X_CE and of its inverse, X_EC_covariance, and from its diagonal
        # X_EC_rotation_std_deg / X_EC_translation_std — compiled, as one call.
        x_CE, x_EC, std, cov = kernels.estimate_outputs(
            np.ascontiguousarray(e._X_CE_hat(), dtype=float),
            np.ascontiguousarray(e.X_CE_covariance, dtype=float))
        return {"X_CE_estimate": x_CE, "X_EC_estimate": x_EC, "X_EC_std": std,
                "X_EC_covariance": cov,
                "status": np.array([mode, e.num_updates, e.num_rejected, nis], dtype=float)}

    def _Collect(self, context, discrete_state, sample):
        if self._M == 0:
            # No self-calibration motions: the estimator starts from the guess, now.
            start = start_estimator(self._config, self._X_CE_guess, [], [], True)
            estimator = start.estimator
            estimator._update(*(vector_to_pose(v) for v in sample.reshape(2, 12)))
            self._SetEstimatorState(discrete_state, estimator, STATUS_INIT_FAILED)
            discrete_state.set_value(self._mode_index, [STATUS_INIT_FAILED])
            return
        phase = float(self._phase_port.Eval(context)[0])
        # discrete_state holds a copy of the current state: the new sample is written into its
        # buffers in place (copying the whole buffer at every sample cost more than the rest).
        keys = discrete_state.get_mutable_vector(self._keys_index).get_mutable_value()
        num_keys = int(context.get_discrete_state(self._num_keys_index).get_value()[0])
        # Key frame 0 is the first sample; key frame k+1 the first sample of phase ≥ k+1.
        if num_keys == 0 or phase >= num_keys:
            keys[num_keys * _SAMPLE:(num_keys + 1) * _SAMPLE] = sample
            num_keys += 1
            discrete_state.set_value(self._num_keys_index, [num_keys])
        buffer = discrete_state.get_mutable_vector(self._buffer_index).get_mutable_value()
        num_buffered = int(context.get_discrete_state(self._num_buffered_index).get_value()[0])
        sample_buffered = num_buffered < self._capacity
        if sample_buffered:
            buffer[num_buffered * _SAMPLE:(num_buffered + 1) * _SAMPLE] = sample
            num_buffered += 1
            discrete_state.set_value(self._num_buffered_index, [num_buffered])
        if num_keys < self._M + 1:
            return
        poses = keys.reshape(-1, 2, 12)
        X_BE_keys = [vector_to_pose(v) for v in poses[:, 0]]
        X_CT_keys = [vector_to_pose(v) for v in poses[:, 1]]
        try:
            X_CE0, mode, from_guess = (two_motion_estimate(X_BE_keys, X_CT_keys,
                                                           self._init_method),
                                       STATUS_FILTERING, False)
        except ValueError:
            # Degenerate self-calibration motions: start from the guess, with a wider
            # covariance, and say so on the status output.
            X_CE0, mode, from_guess = self._X_CE_guess, STATUS_INIT_FAILED, True
        buffered = buffer[:num_buffered * _SAMPLE].reshape(-1, 2, 12)
        start = start_estimator(self._config, X_CE0,
                                [vector_to_pose(v) for v in buffered[:, 0]],
                                [vector_to_pose(v) for v in buffered[:, 1]], from_guess)
        estimator = start.estimator
        if not (sample_buffered and start.used_samples):
            # This sample was not part of the start-up: it is the first on-line one.
            estimator._update(*(vector_to_pose(v) for v in sample.reshape(2, 12)))
        self._SetEstimatorState(discrete_state, estimator, mode)
        discrete_state.set_value(self._output_indices["X_EC_two_motion"],
                                 pose_to_vector(inverse(X_CE0)))
        discrete_state.set_value(self._mode_index, [mode])


def add_hand_eye_calibrator(builder, *, estimator, period: float, X_BE, X_CT,
                            X_EC_initial_guess=None, phase=None, X_CT_valid=None, X_CT_covariance=None,
                            num_self_calibration_motions: int | None = None,
                            name: str = "hand_eye_calibrator", **kwargs) -> HandEyeCalibrator:
    """Adds a ``HandEyeCalibrator`` to any ``DiagramBuilder`` and connects it — no scenario.

    Args:
        builder: the ``DiagramBuilder``.
        estimator: the estimator's settings with their σ (e.g. ``TargetFilter(rotation_sigma=
            0.002, translation_sigma=0.0005)``, rad and m). A σ that understates your camera's
            noise is corrected on-line: the reported ``X_EC_std`` is scaled by the noise the
            measurements show (their mean NIS; see ``HandEyeCalibrator``'s outputs).
        period: the camera's sample period (s).
        X_EC_initial_guess: the camera on the hand, 4×4 (or ``X_CE_initial_guess=`` in
            ``kwargs``, its inverse).
        X_BE, X_CT: output ports of your robot (flange E in base B, 12-vector [vec_row(R); p])
            and of your camera (target T in camera C, same layout), sampled at the same instants.
        phase: output port of the motion index (see the class's "Phases"); None: no
            self-calibration motions (M = 0, the estimator starts from the guess).
        X_CT_valid, X_CT_covariance: optional output ports (a detector's ``found`` and 6×6
            covariance).
        num_self_calibration_motions: M (default 2 with ``phase``, 0 without).
        kwargs: the other arguments of ``HandEyeCalibrator``.

    Returns the calibrator (its outputs: ``X_EC_estimate``, ``X_EC_std``, ``status``, …).
    """
    M = num_self_calibration_motions if num_self_calibration_motions is not None else (
        2 if phase is not None else 0)
    if M and phase is None:
        raise ValueError(f"phase: num_self_calibration_motions = {M} needs the phase output "
                         "port that tells which motion runs (or M = 0 to start from the guess)")
    calibrator = builder.AddNamedSystem(name, HandEyeCalibrator(
        period, X_EC_initial_guess=X_EC_initial_guess, estimator=estimator,
        num_self_calibration_motions=M, **kwargs))
    builder.Connect(X_BE, calibrator.get_X_BE_input_port())
    builder.Connect(X_CT, calibrator.get_X_CT_input_port())
    for port, target in ((phase, calibrator.get_phase_input_port()),
                         (X_CT_valid, calibrator.get_X_CT_valid_input_port()),
                         (X_CT_covariance, calibrator.get_X_CT_covariance_input_port())):
        if port is not None:
            builder.Connect(port, target)
    return calibrator
