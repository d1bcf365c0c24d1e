"""The error of a PyReason feature tracelab does not have (docs/pyreason.md, "What is not supported yet")."""
from __future__ import annotations

from tracelab.errors import UserError


class UnsupportedFeature(UserError):
    """A PyReason feature tracelab does not have; the message names it."""


def unsupported(feature: str, hint: str = "") -> UnsupportedFeature:
    """`feature` (what the user called) is not supported; `hint` what to do instead."""
    return UnsupportedFeature(f"{feature} is not supported by tracelab.pyreason{'; ' + hint if hint else ''} "
                              "(docs/pyreason.md, \"Switching from PyReason\")")
