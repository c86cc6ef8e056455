"""The one base of every error pin_match raises on purpose.

The command line catches exactly this base and prints its one-line message (exit 2);
anything else is a bug, in pin_match or a library, and keeps its traceback. Each
subclass also derives from the builtin that best describes it (``ValueError``,
``OSError``...), so ``except ValueError`` in a caller's code still works.
"""

from __future__ import annotations


class PinMatchError(Exception):
    """A problem the user can fix: bad input, missing weights, an unknown name, a full disk."""
