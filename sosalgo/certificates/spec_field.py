"""A spec's ``certificate:`` field, checked by the families it names (a check of
:mod:`sosalgo.spec.checks`, run by every spec load)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from sosalgo.certificates import (
    FAMILIES,
    family_applies,
    get_family,
    inhomogeneous_functions,
    nonconvex_functions,
)
from sosalgo.spec.loading import operator_functions

if TYPE_CHECKING:  # only for annotations
    from sosalgo.spec.types import Spec

__all__ = ["check_certificate_field"]


def check_certificate_field(spec: Spec, data: Mapping[str, Any],
                            fail: Callable[[str, str], Exception]) -> Spec:
    """``spec`` with its family: ``certificate: NAME`` or ``certificate: {family: NAME,
    <option>: value}`` (default: interpolation for a composite spec, else theorem1). The
    options are checked by the family (:func:`sosalgo.certificates.get_family`), and the
    family must apply to the spec's setting (:func:`sosalgo.certificates.family_applies`)."""
    seed = family_applies(spec, "theorem1") is None  # Theorem 1's setting
    raw = data.get("certificate", "theorem1" if seed else "interpolation")
    known = ", ".join(FAMILIES)
    if isinstance(raw, dict):
        name = raw.get("family")
        if not isinstance(name, str) or name not in FAMILIES:
            raise fail("certificate.family", f"missing or unknown family (known: {known})")
        options = {k: v for k, v in raw.items() if k != "family"}
        for key, val in options.items():
            try:
                get_family(name, {key: val})
            except ValueError as exc:
                what = str(exc).split(": ", 1)[-1]
                raise fail(f"certificate.{str(key)[:40]}", what) from None
    elif not isinstance(raw, str) or raw not in FAMILIES:
        raise fail("certificate", f"unknown family (known: {known})")
    else:
        name, options = raw, {}
    problem = family_applies(spec, name)
    unfit = (nonconvex_functions(spec) or operator_functions(spec)
             or inhomogeneous_functions(spec))
    if problem and ("certificate" in data or not unfit):
        raise fail("certificate", problem)  # a class no family takes: refused where used
    return dataclasses.replace(spec, certificate=name, certificate_options=options,
                               certificate_given="certificate" in data)
