"""The performance estimation problem: the exact worst case of a method over N steps
(:func:`pep`), its dual certificate proven exactly, its worst-case trajectory as a
checked witness (:func:`check_witness`). ``sosalgo pep`` is :func:`sosalgo.pep_run`
(:mod:`sosalgo.runs.pep`: files, resumable sweeps)."""

from sosalgo.worstcase.core import MAX_STEPS, PEPResult, parse_steps, pep
from sosalgo.worstcase.witness import WITNESS_KIND, check_witness

__all__ = ["MAX_STEPS", "PEPResult", "WITNESS_KIND", "check_witness", "parse_steps", "pep"]
