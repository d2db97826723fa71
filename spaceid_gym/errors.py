"""Errors raised for bad user input.

Every input problem (a URDF, a log file, a parameter value) raises :class:`SpaceIdInputError`,
a ``ValueError`` whose message names the file, column or parameter and what was expected. The
``spaceid`` command turns it into a one-line message and a non-zero exit code.
"""

from __future__ import annotations


class SpaceIdInputError(ValueError):
    """Bad input: the message says where (file, column, parameter) and what was expected."""
