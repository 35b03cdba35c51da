"""Benchmarks (``make bench``): speed is measured here against in-run baselines, never in
timed tests."""
