"""The performance estimation problem: the exact worst case of a method over N steps
(:func:`pep`), its dual certificate proven exactly, its worst-case trajectory as a
checked witness (:func:`check_witness`), and ``sosalgo pep`` (:func:`pep_run`)."""

from sosalgo.pep.core import MAX_STEPS, PEPResult, pep
from sosalgo.pep.run import parse_steps, pep_run
from sosalgo.pep.witness import WITNESS_KIND, check_witness

__all__ = ["MAX_STEPS", "PEPResult", "WITNESS_KIND", "check_witness", "parse_steps", "pep",
           "pep_run"]
