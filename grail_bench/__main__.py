"""``python -m grail_bench``: the ``grail-bench`` command."""

from grail_bench.cli import main

if __name__ == "__main__":
    main()
