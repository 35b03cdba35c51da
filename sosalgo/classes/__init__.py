"""Function classes: one module per class, one registry line each.

A class (:class:`~sosalgo.classes.base.FunctionClass`) declares its parameters, the
oracles it answers, its pairwise interpolation inequalities and its quadratics; the spec
loader, the oracle model (:mod:`sosalgo.oracles`) and the interpolation certificate
family read nothing else. To add a class: write a module with a ``FunctionClass``
subclass and add it below (or call :func:`register_class`).
"""

from __future__ import annotations

from sosalgo.classes import convex, indicator, smooth_strongly_convex, strongly_convex
from sosalgo.classes.base import ORACLE_KINDS, FunctionClass, Inequality, convex_form

CLASSES: dict[str, FunctionClass] = {}


def register_class(cls: FunctionClass) -> FunctionClass:
    """Make ``cls`` available under ``cls.name`` in specs' ``functions:``."""
    if not cls.name or not cls.name.isidentifier():
        raise ValueError(f"class name {cls.name!r}: must be an identifier")
    unknown = set(cls.oracles) - set(ORACLE_KINDS)
    if unknown or not cls.oracles:
        raise ValueError(f"class {cls.name}: oracles must be among {', '.join(ORACLE_KINDS)}")
    CLASSES[cls.name] = cls
    return cls


def get_class(name: str) -> FunctionClass:
    """The class registered under ``name`` (KeyError naming the known ones)."""
    try:
        return CLASSES[name]
    except KeyError:
        raise KeyError(f"unknown class {name!r} (known: {', '.join(CLASSES)})") from None


register_class(smooth_strongly_convex.CLASS)
register_class(convex.CLASS)
register_class(strongly_convex.CLASS)
register_class(indicator.CLASS)

__all__ = ["CLASSES", "FunctionClass", "Inequality", "ORACLE_KINDS", "convex_form",
           "get_class", "register_class"]
