"""The report's start-up stays light: its modules import neither torch nor scipy.special, and a leaderboard names
configurations from the recognizers' kept descriptions without importing them."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from grail_bench.harness.ceiling_cache import CeilingCache
from grail_bench.harness.store import ResultsStore
from grail_bench.recognizers import descriptions
from grail_bench.recognizers.registry import build, recognizer_info, register_recognizer, unregister_recognizer

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("torch", "stable_baselines3", "scipy.special")


def _python(code: str, cache: Path | None = None) -> list[str]:
    """Run ``code`` in a fresh interpreter (this checkout first on the path); its printed JSON list."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    if cache is not None:
        env["GRAIL_BENCH_CACHE"] = str(cache)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_the_cli_and_the_report_import_no_torch_and_no_scipy_special():
    loaded = _python("import json, sys\n"
                     "import grail_bench.cli.app, grail_bench.report.leaderboard, grail_bench.report.summary\n"
                     "import grail_bench.report.text, grail_bench.report.claims, grail_bench.report.configs\n"
                     f"print(json.dumps([m for m in {list(HEAVY)!r} if m in sys.modules]))")
    assert loaded == []


def test_a_kept_description_is_read_without_importing_the_recognizer(tmp_path):
    cache = tmp_path / "cache"
    code = ("import json, sys\n"
            "from grail_bench.recognizers import descriptions\n"
            "named = descriptions.named('bc')\n"
            "rows = [named.paper_name, named.default_scorer, named.reference,\n"
            "        descriptions.settings('bc', None), descriptions.settings('bc', '{\"n_epochs\": 7}'),\n"
            "        descriptions.settings('bc', '{\"no_such_setting\": 1}'), descriptions.named('no-such') is None]\n"
            "descriptions.save()\n"
            "print(json.dumps(rows + ['torch' in sys.modules]))")
    first = _python(code, cache)
    info = recognizer_info("bc")
    built = json.dumps(build("bc", {"n_epochs": 7}).config, sort_keys=True, default=str)
    assert first[:3] == [info.paper_name, info.default_scorer, info.reference]
    assert first[3] == json.dumps(build("bc").config, sort_keys=True, default=str) and first[4] == built
    assert first[5] is None and first[6] is True and first[7] is True  # described from the recognizer itself
    assert _python(code, cache) == first[:7] + [False]  # the second process reads what the first kept


@pytest.mark.parametrize("text", ['{"named": {"bc": {"paper_name": "WRONG"',
                                  '{"named": {"bc": {"paper_name": "WRONG", "default_scorer": 3, "reference": false}}, '
                                  '"settings": {}}'])
def test_a_malformed_cache_file_is_described_again(tmp_path, monkeypatch, text):
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path))
    descriptions.forget()
    path = tmp_path / "recognizers" / f"{descriptions.fingerprint()}.json"
    path.parent.mkdir(parents=True)
    path.write_text(text, encoding="utf-8")
    try:
        assert descriptions.named("bc").paper_name == recognizer_info("bc").paper_name
        descriptions.save()
        assert json.loads(path.read_text(encoding="utf-8"))["named"]["bc"]["paper_name"] != "WRONG"
    finally:
        descriptions.forget()


def test_nothing_is_kept_while_a_recognizer_registered_in_this_process_is_in_play(tmp_path, monkeypatch):
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path))
    descriptions.forget()
    register_recognizer("local-bc", "grail_bench.recognizers.bc:BCRecognizer")
    try:
        assert descriptions.fingerprint() is None
        assert descriptions.named("local-bc").paper_name == recognizer_info("bc").paper_name
        descriptions.save()
        assert not (tmp_path / "recognizers").exists()
    finally:
        unregister_recognizer("local-bc")
        descriptions.forget()


def test_a_fingerprint_changes_with_the_code(tmp_path, monkeypatch):
    sources = tmp_path / "grail_bench"
    sources.mkdir()
    (sources / "a.py").write_text("X = 1\n", encoding="utf-8")
    monkeypatch.setattr(descriptions, "_SOURCES", sources)
    first = descriptions.fingerprint()
    (sources / "a.py").write_text("X = 2\n", encoding="utf-8")
    assert first is not None and descriptions.fingerprint() not in (None, first)


@pytest.mark.parametrize("read_only", [True, False])
def test_a_read_only_ceiling_cache_reads_the_store_and_never_writes_it(tmp_path, read_only):
    path = tmp_path / "results.sqlite"
    with ResultsStore(path) as store:
        store.create()
    assert CeilingCache(path).put({"a": "{}"}) is True
    before = path.read_bytes()
    cache = CeilingCache(path, read_only=read_only)
    assert cache.get(["a", "b"]) == {"a": "{}"}
    assert cache.put({"b": "{}"}) is (not read_only)
    assert (path.read_bytes() == before) is read_only
