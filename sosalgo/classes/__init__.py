"""Function classes: one module per class, one registry line each.

A class (:class:`~sosalgo.classes.base.FunctionClass`) owns everything known about it:
its parameters, the oracles it answers, its pairwise interpolation inequalities (float and
exact), its quadratics, its listing text, its test functions, the facts the witnesses,
design floors and noise analysis rely on. The rest of sosalgo asks the class and names
none (a test checks it). To add a class: write a module with a ``FunctionClass`` subclass
and add it below (or call :func:`register_class`); docs/classes.md.
"""

from __future__ import annotations

from sosalgo.classes import (
    bounded_indicator,
    cocoercive,
    cocoercive_strongly_monotone_expensive,
    convex,
    convex_lipschitz,
    convex_qg,
    convex_support,
    indicator,
    linear_operator,
    lipschitz_map,
    lipschitz_operator,
    lipschitz_strongly_monotone,
    lipschitz_strongly_monotone_expensive,
    monotone,
    nonexpansive,
    relatively_smooth,
    rsi_eb,
    skew_symmetric_linear_operator,
    smooth,
    smooth_convex_lipschitz,
    smooth_lojasiewicz,
    smooth_lojasiewicz_expensive,
    smooth_lojasiewicz_intermediate,
    smooth_strongly_convex,
    smooth_strongly_convex_quadratic,
    strongly_convex,
    strongly_monotone,
    symmetric_linear_operator,
    weakly_convex,
)
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


def unregister_class(name: str) -> None:
    """Remove the class registered under ``name`` (the shipped ones stay)."""
    if CLASSES.get(name) in _SHIPPED:
        raise ValueError(f"class {name}: shipped classes cannot be removed")
    CLASSES.pop(name, None)


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
register_class(smooth.CLASS)
register_class(monotone.CLASS)
register_class(strongly_monotone.CLASS)
register_class(cocoercive.CLASS)
register_class(lipschitz_operator.CLASS)
register_class(nonexpansive.CLASS)
register_class(lipschitz_strongly_monotone.CLASS)
register_class(convex_lipschitz.CLASS)
register_class(convex_qg.CLASS)
register_class(rsi_eb.CLASS)
register_class(smooth_lojasiewicz.CLASS)
register_class(smooth_lojasiewicz_intermediate.CLASS)
register_class(smooth_lojasiewicz_expensive.CLASS)
register_class(lipschitz_strongly_monotone_expensive.CLASS)
register_class(cocoercive_strongly_monotone_expensive.CLASS)
register_class(smooth_convex_lipschitz.CLASS)
register_class(bounded_indicator.CLASS)
register_class(relatively_smooth.CLASS)
register_class(relatively_smooth.ADAPTABLE)
register_class(smooth_strongly_convex_quadratic.CLASS)
register_class(linear_operator.CLASS)
register_class(symmetric_linear_operator.CLASS)
register_class(skew_symmetric_linear_operator.CLASS)
register_class(weakly_convex.CLASS)
register_class(weakly_convex.SMOOTH)
register_class(convex_support.CLASS)
register_class(lipschitz_map.CLASS)
_SHIPPED = tuple(CLASSES.values())

SEED_CLASS: FunctionClass = smooth_strongly_convex.CLASS  # F(m, L): a spec without functions:

__all__ = ["CLASSES", "FunctionClass", "Inequality", "ORACLE_KINDS", "SEED_CLASS",
           "convex_form", "get_class", "register_class", "unregister_class"]
