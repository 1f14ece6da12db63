"""Provenance stamps: what a stored row says about the run that made it."""

from __future__ import annotations

import json
import re

from grail_bench.core.provenance import git_commit, stamp


def test_stamp_names_command_machine_and_date():
    data = json.loads(stamp(["/somewhere/bin/grail-bench", "run", "-r", "bc"]))
    assert data["command"] == ["grail-bench", "run", "-r", "bc"]  # the program's name, not the path
    assert data["cores"] >= 1 and data["python"].startswith("3.11") and data["cpu"]
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\+00:00", data["date"])


def test_commit_is_a_sha_possibly_dirty_or_unknown():
    commit = git_commit()
    assert commit is None or re.fullmatch(r"[0-9a-f]{40}(\+dirty)?", commit)
