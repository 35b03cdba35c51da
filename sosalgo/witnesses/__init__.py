"""Witnesses of how bad a method can get, checked exactly: cycles (non-convergence,
:mod:`sosalgo.witnesses.cycles`) and witnessed lower bounds on the worst-case linear rate
(rate brackets, :mod:`sosalgo.witnesses.brackets`); :mod:`sosalgo.witnesses.rows` gives
``analyze`` its fields. Nothing is imported here, so that the brackets stay light (no
sympy): import the submodules.
"""
