"""The command line: thin commands (:mod:`.app`) over the library, and the input checks they share (:mod:`.inputs`)."""

from grail_bench.cli.app import app, main

__all__ = ["app", "main"]
