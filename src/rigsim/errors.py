"""Errors the ``rigsim`` command reports as one line (``rigsim: error: ...``, exit 2).

Defined here, not in rigsim.cli, so that ``python -m rigsim.cli`` (where cli is ``__main__``) and
the procedure modules that raise it share one class.
"""


class CliError(Exception):
    """Bad command-line input: the message names the option, the value and the allowed range."""
