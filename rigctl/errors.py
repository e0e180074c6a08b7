"""The one error hierarchy of rigctl.

Every error a user can cause derives from :class:`RigctlError`. The CLI prints ``str(error)`` as one line
on stderr and exits with :attr:`RigctlError.exit_code`; nothing else reaches the user unless ``--debug``.
Each message names the file, field, device or byte offset concerned and, where it can, what to do.
"""

from __future__ import annotations


class RigctlError(Exception):
    """Base of every error a user can cause or act on. Exit code 2 at the CLI."""

    exit_code = 2


class RigFileError(RigctlError):
    """A rig file cannot be read, is not valid YAML, or breaks the schema.

    The message starts with ``path:line:`` and names the field, e.g.
    ``rigs/x.yaml:12: grid.spacing_x_m must be > 0, got -0.12``.
    """


class SpecVersionError(RigFileError):
    """A file (rig, take manifest, calibration) declares a newer ``spec`` than this rigctl understands."""


class ParameterError(RigctlError, ValueError):
    """A numeric parameter is out of its domain (zero, negative, NaN, far < near, ...).

    Raised by the planner and processing functions before any arithmetic could turn it into NaN or
    infinity; the message names the parameter and the offending value.
    """


class DeviceError(RigctlError):
    """A device named in a rig file is missing, busy, or does not do what the rig asks of it."""


class TakeError(RigctlError):
    """A take on disk is missing, unreadable, or inconsistent; the message names file and byte offset."""


class ProtocolError(RigctlError):
    """Bytes on a wire do not form a valid message of the protocol being decoded."""


class CalibrationError(RigctlError):
    """Calibration input cannot constrain a calibration; the message says which camera and what to shoot."""
