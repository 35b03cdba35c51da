"""Table 1 of the paper: the certified rate of each spec beside its closed-form rate."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from sosalgo.analysis import analyze_spec
from sosalgo.certificates import CertificateFamily
from sosalgo.schema import TABLE1_COLUMNS, TABLE1_FILE
from sosalgo.spec import Spec
from sosalgo.spec.references import reference_values
from sosalgo.store import write_table

__all__ = ["TABLE1_COLUMNS", "table1_rows", "write_table1"]


def table1_rows(specs: Sequence[Spec], kappas: Sequence[float], tol: float,
                families: Sequence[Sequence[CertificateFamily | None]],
                ) -> tuple[list[dict[str, Any]], list[str]]:
    """(rows, columns): one row per spec and kappa. The closed-form rate of a spec is the
    first entry of its ``references``. ``families[i]`` lists the families to run on spec i
    (None: the spec's own); the first fills ``rho_certified`` (and ``family`` when it is not
    the default, and ``lag`` when its certificate has one), every further one adds
    rho_<family>, certified_<family>, difference_<family> (and lag_<family>)."""
    rows = []
    extra_cols: list[str] = []
    for spec, fams in zip(specs, families, strict=True):
        for k in kappas:
            row = _row(spec, k, tol, fams)
            extra_cols += [c for c in row if c not in extra_cols]
            rows.append(row)
    return rows, TABLE1_COLUMNS + [c for c in extra_cols if c not in TABLE1_COLUMNS]


def _row(spec: Spec, kappa: float, tol: float,
         fams: Sequence[CertificateFamily | None]) -> dict[str, Any]:
    refs = reference_values(spec, kappa)
    name, val = next(iter(refs.items()), ("", None))
    row: dict[str, Any] = {"spec": spec.name, "kappa": float(kappa)}
    for i, fam in enumerate(fams):
        res = analyze_spec(spec, kappa, tol=tol, family=fam)
        diff = None if (res.rho is None or val is None) else res.rho - val
        if i == 0:
            row.update({"rho_certified": res.rho, "certified": res.certified,
                        "closed_form": name, "closed_form_rate": val, "difference": diff})
            if fam is not None and not fam.is_default:
                row["family"] = fam.name
                if res.lag is not None:
                    row["lag"] = res.lag
        else:
            row.update({f"rho_{fam.name}": res.rho, f"certified_{fam.name}": res.certified,
                        f"difference_{fam.name}": diff})
            if res.lag is not None:
                row[f"lag_{fam.name}"] = res.lag
    return row


def write_table1(out_dir: Path, rows: Sequence[Mapping[str, Any]], cols: Sequence[str],
                 settings: dict[str, Any]) -> Path:
    """``out_dir/table1.csv``, replaced whole under the run model
    (:func:`sosalgo.store.write_table`: a table of other settings is kept aside)."""
    path = out_dir / TABLE1_FILE
    write_table(path, cols, rows, settings)
    return path
