"""Statistics as pure functions over arrays: per-seed metrics, robust aggregates, verdicts.

Above :mod:`grail_bench.core` only: the harness uses them per seed and across
seeds, the reports to summarise; nothing here formats or draws.
"""
