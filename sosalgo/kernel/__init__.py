"""The numeric kernel (layer 0): safe expressions, exact and ball arithmetic, conic data,
the one door to the conic solvers, the process pool, interruption handling, resource
budgets. It imports nothing of sosalgo but :mod:`sosalgo.errors` and itself."""
