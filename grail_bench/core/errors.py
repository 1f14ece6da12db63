"""The one exception type that means bad input.

Everything a user can get wrong (an unknown name, a malformed card, a wrong
parameter, a corrupt store, a plugin breaking the contract) raises a
:class:`UserError`. The command line reports these in one line with exit code
2; any other exception is a bug and shows its traceback.
"""

from __future__ import annotations


class UserError(ValueError):
    """Bad input, reported in one line (a ``ValueError``, so callers catching that keep working)."""
