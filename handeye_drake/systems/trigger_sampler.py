"""A zero-order hold that samples at the instant a rendered camera takes its image.

Drake's Simulator handles the events of one instant in three phases: unrestricted updates, then
discrete updates, then publishes; each phase computes every system's update from the same
context and applies them together. ``TargetDetector`` reads (renders) its image in an
unrestricted update, and so does a ``MultibodyPlant`` with sampled output ports (Drake's
default) step its state. A ``ZeroOrderHold`` samples in the discrete phase: when a plant step
falls on the camera trigger (every 3rd frame for a 2 ms plant and a 30 Hz camera), it samples
the plant after that step, one plant step later than the image — 0.03 mm and 0.06 mrad at the
servo's speeds, but 10–30 standard deviations of a rendered pose measurement (measured). This
hold samples in the unrestricted phase, so the robot pose it holds is the one the image shows.
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem

from ..estimation.validation import check_positive


class CameraTriggerSampler(LeafSystem):
    """Samples its vector input every ``period`` seconds from ``offset`` on (and at
    initialization), in an unrestricted update, and holds it.

    Input port:
        u (``size``): any vector (e.g. the robot pose X_BE, [vec_row(R); p (m)]).
    Output port:
        y (``size``): the last sample (zeros before the first one).
    """

    def __init__(self, period: float, size: int, offset: float = 0.0):
        LeafSystem.__init__(self)
        self._period = check_positive(period, "period")
        offset = check_positive(offset, "offset", allow_zero=True)
        if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or size < 1:
            raise ValueError(f"size: expected an integer ≥ 1, got {size!r}")
        self._input = self.DeclareVectorInputPort("u", int(size))
        self._index = self.DeclareDiscreteState(int(size))
        self.DeclarePeriodicUnrestrictedUpdateEvent(self._period, offset, self._Sample)
        self.DeclareInitializationUnrestrictedUpdateEvent(self._Sample)
        self._output = self.DeclareStateOutputPort("y", self._index)

    @property
    def period(self) -> float:
        return self._period

    def _Sample(self, context, state):
        state.get_mutable_discrete_state().get_mutable_vector(self._index).SetFromVector(
            self._input.Eval(context))
