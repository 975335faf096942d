"""Errors meant for people, and the exit status each one gives.

Every problem a user can cause (a bad model id, a value out of range, a malformed file) raises
:class:`MatremapError` with one sentence naming the problem and, where there is one, the fix. The command
line prints that sentence on stderr and exits with the error's :attr:`~MatremapError.exit_code`:

====  ========================================================================================
code  meaning
====  ========================================================================================
0     converted, and every measure of the quality gate within its threshold
2     bad input or usage (:class:`MatremapError`): nothing was written
3     converted, but the result failed the quality gate (:class:`QualityGateFailed`): the files are in
      the output folder and its report says FAILED and why
4     a renderer or the environment failed (:class:`RendererUnavailable`): not installed, crashed,
      timed out; nothing was written and nothing was cached, so a retry after the fix starts afresh
70    an internal error (a bug, not the input): one line naming the exception; ``matremap --debug ...``
      shows the traceback
130   interrupted
====  ========================================================================================
"""

from __future__ import annotations

#: exit status of a converted result that failed the quality gate
EXIT_QUALITY = 3
#: exit status of a renderer or environment failure
EXIT_RENDERER = 4
#: exit status of an unexpected exception (a bug): BSD's EX_SOFTWARE
EXIT_INTERNAL = 70
#: exit status when interrupted (128 + SIGINT)
EXIT_INTERRUPTED = 130


class MatremapError(ValueError):
    """A user-facing error: the message names the problem and how to fix it (exit status 2)."""

    exit_code = 2


class RendererUnavailable(MatremapError):
    """A renderer cannot be used here (not installed, crashed, timed out): the environment, not the input.
    Never cached as a result; exit status 4."""

    exit_code = EXIT_RENDERER


class QualityGateFailed(MatremapError):
    """The result was written but failed the quality gate; the message gives the worst measure (exit 3)."""

    exit_code = EXIT_QUALITY


class TransformChecksumError(MatremapError):
    """A transform file's content does not match the checksum stored in it (edited or damaged since it was
    written), or a transform that must carry one has none. A cached transform that fails this is
    recomputed; a shipped one means a damaged installation."""
