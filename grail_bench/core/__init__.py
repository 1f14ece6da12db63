"""The bottom layer: what every other layer may use and that uses none of them.

Errors, file locations, seeding (per-goal and per-cell random streams),
entry-point plugin lookup, the trajectory types, the on-disk model cache, run
provenance, and small torch and SB3 helpers. Nothing here imports another
grail-bench layer (``lint-imports`` checks it).
"""
