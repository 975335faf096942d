"""Errors meant for people.

Every problem a user can cause (a bad model id, a value out of range, a malformed file) raises
:class:`MatremapError` with one sentence naming the problem and, where there is one, the fix.
The CLI prints that sentence on stderr and exits with status 2.
"""

from __future__ import annotations


class MatremapError(ValueError):
    """A user-facing error: the message names the problem and how to fix it."""
