"""Deprecated: the page's replay viewer and the frames of ``earthbench show --animate`` moved to
:mod:`earthbench.playback` after 0.2.0, so that this name no longer sounds like the referee's replay
state (:mod:`earthbench.referee.state`)."""

from . import compat

__getattr__ = compat.forward(__name__)
