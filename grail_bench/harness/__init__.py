"""The harness layer: planning, sweeps and their executors, the results store, modes and Bayes ceilings.

* :mod:`.planning`: recognizers checked and hashed once; fitting; score checks.
* :mod:`.modes`: offline, online and open set, each a row type, a per-seed run, an aggregation and columns.
* :mod:`.sweep`, :mod:`.executors`: units run serially, on a process pool or on Ray; the driver stores rows.
* :mod:`.store`: the SQLite results store; its tables in :mod:`.schema`, their migrations in :mod:`.migrations`,
  the Bayes ceilings it caches in :mod:`.ceiling_cache`.
* :mod:`.ceiling`: Bayes ceilings. :mod:`.api`: :func:`evaluate`.
"""
