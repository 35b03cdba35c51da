"""One error hierarchy (modelled on cvxpy's ``error.py``): every error sosalgo raises on
purpose is a :class:`SosalgoError`; the CLI maps the kind to an exit code.

* :class:`InputError` — bad input or environment (spec, options, files, cluster): exit 2.
* :class:`VerificationError` — a certificate does not pass its check: exit 3.
"""

from __future__ import annotations

__all__ = ["SosalgoError", "InputError", "VerificationError"]


class SosalgoError(Exception):
    """Base of every error sosalgo raises on purpose."""


class InputError(SosalgoError, ValueError):
    """Bad input or environment; the message is one line naming the file and field.

    ``names_file`` is False for errors raised where the file is unknown (the numeric
    model): the CLI then puts the spec's path in front."""

    names_file = True


class VerificationError(SosalgoError):
    """A certificate failed its exact or simulation check."""
