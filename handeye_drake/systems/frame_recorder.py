"""Keeps a few camera frames of a simulation, for pictures of what the detector saw."""

from __future__ import annotations

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem
from pydrake.systems.sensors import ImageRgba8U

from ..estimation.validation import check_positive

#: Requests this close before a sample time (s) are taken at that sample (rounding of k·period).
_TIME_TOLERANCE = 1e-9


class _Frames(tuple):
    """The recorded frames. Drake deep-copies abstract state (``copy.deepcopy``) whenever it
    clones a state, at every unrestricted update; the frames are never modified in place (a new
    tuple replaces the old one), so sharing them is safe and saves copying megabytes of images
    at every sample."""

    def __deepcopy__(self, memo):
        return self


class FrameRecorder(LeafSystem):
    """Copies the colour image at the first camera sample (t = k·``period`` + ``offset``) at or
    after each requested time, into its abstract state; nothing is evaluated at other samples,
    so it costs no rendering. It samples in an unrestricted update, at the same instants as
    ``TargetDetector`` (whose update is unrestricted too), so it sees the very image the detector
    measured (the same cached render).

    Input port:
        color_image (abstract ``ImageRgba8U``).
    State (``frames(context)``): a tuple of (request index, sample time (s), H×W×4 uint8 RGBA).
    """

    def __init__(self, times, period: float, offset: float = 0.0):
        LeafSystem.__init__(self)
        try:
            times = [float(t) for t in times]
        except (TypeError, ValueError):
            raise ValueError(f"times: expected a list of times (s), got {times!r}") from None
        for i, t in enumerate(times):
            if not math.isfinite(t) or t < 0:
                raise ValueError(f"times[{i}]: expected a finite time ≥ 0 s, got {t!r}")
        self._times = times
        self._period = check_positive(period, "period")
        self._offset = check_positive(offset, "offset", allow_zero=True)
        self._image_port = self.DeclareAbstractInputPort("color_image",
                                                         AbstractValue.Make(ImageRgba8U()))
        self._frames_index = self.DeclareAbstractState(AbstractValue.Make(_Frames()))
        self.DeclarePeriodicUnrestrictedUpdateEvent(self._period, self._offset, self._Record)
        self.DeclareInitializationUnrestrictedUpdateEvent(self._Record)

    def get_color_image_input_port(self):
        return self._image_port

    @property
    def times(self) -> list[float]:
        return list(self._times)

    def frames(self, context) -> tuple:
        """The recorded (request index, time, RGBA image) triples in ``context`` (this
        system's), in recording order."""
        return context.get_abstract_state(self._frames_index).get_value()

    def _Record(self, context, state) -> None:
        t = context.get_time()
        frames = context.get_abstract_state(self._frames_index).get_value()
        done = {index for index, _, _ in frames}
        due = [i for i, t_req in enumerate(self._times)
               if i not in done and t_req <= t + _TIME_TOLERANCE]
        if not due:
            return
        image = np.array(self._image_port.Eval(context).data, dtype=np.uint8)
        state.get_mutable_abstract_state(self._frames_index).set_value(
            _Frames(tuple(frames) + tuple((i, t, image) for i in due)))
