"""Batch runs: the executor (serial, processes, Dask) and the sweeps built on it and on
the resumable CSV store (:mod:`sosalgo.store`): kappa sweeps of analyze and design, grids."""
