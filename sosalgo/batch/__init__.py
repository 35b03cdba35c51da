"""Batch runs: the executor (serial, processes, Dask), the resumable CSV store, and the
sweeps built on them (kappa sweeps of analyze and design, grids)."""
