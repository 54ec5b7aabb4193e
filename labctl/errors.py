"""User-facing error types: anything raised as these is reported as one line, never a traceback."""

from __future__ import annotations


class LabctlError(Exception):
    """A problem the user can fix (bad input file, bad value, missing device); message names what and why."""


class InputError(LabctlError, ValueError):
    """Bad user input: names the file/field/value and what was expected."""


class ModelDomainError(InputError):
    """A model was asked for a value outside the range where it is defined or valid."""
