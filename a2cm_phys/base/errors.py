"""The one base of every error a user's input can cause.

A :class:`UserError` is a mistake in what a user gave (an option, a scenario key, a file,
a run another process writes) or an input that cannot be used; its message names the
option, key or file. Each layer raises its own kind (``ConfigError``, ``LogError``,
``RunBusy``, ``UsageError``, …); the commands print any of them as one line ``error: …``
and exit 2 (:func:`a2cm_phys.commands.options.run_cli`). Defined at the bottom of the
package so that no layer needs a layer above it to raise one.
"""

from __future__ import annotations


class UserError(Exception):
    """A user's mistake or an unusable input; the message says which and why."""
