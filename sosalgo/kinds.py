"""The names of the result kinds: the ``kind`` field of every JSON document sosalgo writes.

Plain strings that any layer may stamp on what it builds (a PEP witness, a pareto front);
the registry of what each kind holds, its files and its check is
:data:`sosalgo.documents.KINDS`. Imports nothing.
"""

ANALYSIS_KIND, DESIGN_KIND, GRID_KIND, PARETO_KIND = "analysis", "design", "grid", "pareto"
PEP_KIND, WITNESS_KIND, TABLE1_KIND, FIG4_KIND = "pep", "pep-witness", "table1", "fig4"
CERTIFICATE_KIND, DESIGN_CERTIFICATES_KIND = "certificate", "design-certificates"
VERIFICATION_KIND = "verification"
DESIGN_STEPS_KIND = "design-steps"
ALLK_KIND = "all-k"

__all__ = ["ALLK_KIND",
           "ANALYSIS_KIND", "CERTIFICATE_KIND", "DESIGN_CERTIFICATES_KIND", "DESIGN_KIND",
           "DESIGN_STEPS_KIND",
           "FIG4_KIND", "GRID_KIND", "PARETO_KIND", "PEP_KIND", "TABLE1_KIND",
           "VERIFICATION_KIND", "WITNESS_KIND"]
