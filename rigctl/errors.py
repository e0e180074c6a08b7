"""The one error hierarchy of rigctl.

Every error a user can cause derives from :class:`RigctlError`. The CLI prints ``str(error)`` as one line
on stderr and exits with :attr:`RigctlError.exit_code`; nothing else reaches the user unless ``--debug``.
Each message names the file, field, device or byte offset concerned and, where it can, what to do.

Exit codes, one per class of error, so a script can tell a missing device from a bad file:

====  ==========================================================================================
0     success
1     a check failed (``take check`` found problems, ``control`` a setting not confirmed, ...)
2     usage: a bad option or parameter value (:class:`ParameterError`, argparse)
3     bad input file: rig file, take, calibration, grid (:class:`RigFileError`, :class:`TakeError`,
      :class:`CalibrationError`); an input path too long or looping (:class:`InputPathError`)
4     device: missing, busy, failing, or speaking garbage (:class:`DeviceError`, :class:`ProtocolError`);
      an output destination that is read-only, full or busy (:class:`OutputError`, :class:`DiskFullError`)
5     data damaged: a frame fails its checksum or is missing (:class:`DamagedDataError`); also the exit
      status of a run that completed with ``--skip-damaged`` and left damaged frames out
130   interrupted (Ctrl-C)
====  ==========================================================================================
"""

from __future__ import annotations

import os

EXIT_OK = 0
EXIT_CHECK_FAILED = 1
EXIT_USAGE = 2
EXIT_BAD_INPUT = 3
EXIT_DEVICE = 4
EXIT_DAMAGED = 5
EXIT_INTERRUPTED = 130


class RigctlError(Exception):
    """Base of every error a user can cause or act on. Exit code 2 (usage) at the CLI unless a subclass says."""

    exit_code = EXIT_USAGE


class InputPathError(RigctlError):
    """An input path the system cannot even look up: too long for it (``ENAMETOOLONG``) or a loop of symbolic
    links (``ELOOP``). Exit status 3 (bad input): the path given is at fault, not a destination."""

    exit_code = EXIT_BAD_INPUT


def short_path(path: str | os.PathLike[str] | bytes, keep: int = 40) -> str:
    """``path`` for a one-line message: whole when short, else its start and end around ``...`` and its length
    (a 5,000-character path would bury the message)."""
    text = os.fsdecode(path).encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    if len(text) <= 3 * keep:
        return text
    return f"{text[:keep]}...{text[-keep:]} ({len(text):,} characters)"


class RigFileError(RigctlError):
    """A rig file cannot be read, is not valid YAML, or breaks the schema.

    The message starts with ``path:line:`` and names the field, e.g.
    ``rigs/x.yaml:12: grid.spacing_x_m must be > 0, got -0.12``.
    """

    exit_code = EXIT_BAD_INPUT


class SpecVersionError(RigFileError):
    """A file (rig, take manifest, calibration) declares a newer ``spec`` than this rigctl understands."""


class ParameterError(RigctlError, ValueError):
    """A numeric parameter is out of its domain (zero, negative, NaN, far < near, ...).

    Raised by the planner and processing functions before any arithmetic could turn it into NaN or
    infinity; the message names the parameter and the offending value.
    """


class DeviceError(RigctlError):
    """A device named in a rig file is missing, busy, or does not do what the rig asks of it."""

    exit_code = EXIT_DEVICE


class TakeError(RigctlError):
    """A take on disk is missing, unreadable, or inconsistent; the message names file and byte offset."""

    exit_code = EXIT_BAD_INPUT


class DiskFullError(TakeError):
    """A destination ran out of space; the take ends cleanly and stays readable. Exit status 4: the
    destination (a device) cannot do what the take needs, the input was fine."""

    exit_code = EXIT_DEVICE


class OutputError(DeviceError):
    """An output cannot be written where the user asked: a read-only or full destination, a file where a folder
    is needed, a path that is not UTF-8, a folder another rigctl run is writing. Exit status 4 (the
    destination); the message names the path."""


class PreflightError(RigctlError):
    """Preflight found a reason not to record; ``--force`` records anyway where that is safe to try."""

    def __init__(self, message: str, problems: list[str] | None = None, forcible: bool = False) -> None:
        super().__init__(message)
        self.problems = problems or [message]
        self.forcible = forcible  # every reason is one a user may choose to record through


class DamagedDataError(TakeError):
    """A frame a take claims fails its checksum, is cut short or missing: never passed on silently.

    The message names the file and byte offset; ``--skip-damaged`` leaves such frames out instead.
    """

    exit_code = EXIT_DAMAGED


class BridgeNak(DeviceError):
    """An SDI camera-control bridge answered, and refused."""


class ProtocolError(RigctlError):
    """Bytes on a wire do not form a valid message of the protocol being decoded."""

    exit_code = EXIT_DEVICE


class CalibrationError(RigctlError):
    """Calibration input cannot constrain a calibration, or a calibration makes no sense; the message says
    which camera and what to do."""

    exit_code = EXIT_BAD_INPUT
