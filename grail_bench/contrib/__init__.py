"""Recognizers shipped beside the built-in ones but written as a third-party package would write them.

Each module here imports only grail-bench's public layers (``grail_bench.core``, the recognizer contract in
``grail_bench.recognizers.contract`` and the public names of the scoring and policy modules) and is registered
through the same ``grail_bench.recognizers`` entry-point group a plugin package uses, never through harness,
report or task internals: they show, and test, that the public recognizer contract is enough to add a method.
"""
