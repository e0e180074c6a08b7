"""Capture: one take from the rig's cameras to disk.

:func:`record_take` (:mod:`.recording`) runs preflight (:mod:`.preflight`: can each destination keep up; go,
warn or refuse) and then the :class:`Recorder` (:mod:`.recorder`: per camera a capture thread, a buffer pool
and a writer thread, from one instant T0 to T1), which keeps time with the cameras through :mod:`.pacing`
(live, or paced by a deterministic simulation). The cameras come from :mod:`rigctl.registry`; the take on
disk is :mod:`rigctl.take`'s."""

from rigctl.capture.pacing import Pacing
from rigctl.capture.preflight import PreflightReport, Verdict, WriteSpeed, check_destinations, measure_write
from rigctl.capture.recorder import Recorder, TakePlan
from rigctl.capture.recording import DropWatch, TakeResult, enforce, preflight_take, record_take

__all__ = [
    "DropWatch",
    "Pacing",
    "PreflightReport",
    "Recorder",
    "TakePlan",
    "TakeResult",
    "Verdict",
    "WriteSpeed",
    "check_destinations",
    "enforce",
    "measure_write",
    "preflight_take",
    "record_take",
]
