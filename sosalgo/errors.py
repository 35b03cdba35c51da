"""One error hierarchy (modelled on cvxpy's ``error.py``): every error sosalgo raises on
purpose is a :class:`SosalgoError`; the CLI maps the kind to an exit code.

* :class:`InputError` — bad input or environment (spec, options, files, cluster): exit 2;
  :class:`ModelError` (the numeric model: a point where the spec cannot be evaluated) is one.
* :class:`VerificationError` — a certificate does not pass its check: exit 3.
"""

from __future__ import annotations

__all__ = ["SosalgoError", "InputError", "ModelError", "VerificationError"]


class SosalgoError(Exception):
    """Base of every error sosalgo raises on purpose."""


class InputError(SosalgoError, ValueError):
    """Bad input or environment; the message is one line naming the file and field.

    ``names_file`` is False for errors raised where the file is unknown (the numeric
    model): the CLI then puts the spec's path in front."""

    names_file = True


class ModelError(InputError):
    """The spec cannot be evaluated at this point (domain error, no fixed point, ...)."""

    names_file = False

    def __init__(self, field_: str, message: str):
        self.field = field_
        self.message = message
        super().__init__(f"{field_}: {message}")


class VerificationError(SosalgoError):
    """A certificate failed its exact or simulation check."""
