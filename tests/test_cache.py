"""The trained-model cache: round trip, and every kind of bad file is retrained."""

from __future__ import annotations

import pytest
import torch

from grail_bench.core.cache import CacheWarning, cached_state_dict, key_digest

KEY = {"goal": [0.1, 0.1, 0.05], "seed": 0}


def trainer(calls: list):
    def train():
        calls.append(1)
        return {"w": torch.arange(4.0)}
    return train


def test_round_trip_trains_once(tmp_path):
    calls = []
    state, seconds = cached_state_dict("m", KEY, trainer(calls), root=tmp_path)
    again, seconds_again = cached_state_dict("m", KEY, trainer(calls), root=tmp_path)
    assert calls == [1] and torch.equal(state["w"], again["w"]) and seconds_again == pytest.approx(seconds)
    cached_state_dict("m", {**KEY, "seed": 1}, trainer(calls), root=tmp_path)
    assert calls == [1, 1]


@pytest.mark.parametrize("damage", ["corrupt", "truncate", "checksum", "other_key", "no_meta"])
def test_unusable_entries_are_reported_and_retrained(tmp_path, damage):
    calls = []
    cached_state_dict("m", KEY, trainer(calls), root=tmp_path)
    weights = tmp_path / "m" / f"{key_digest(KEY)}.pt"
    meta = weights.with_suffix(".json")
    if damage == "corrupt":
        weights.write_bytes(b"\x00" * 64)
    elif damage == "truncate":
        weights.write_bytes(weights.read_bytes()[:20])
    elif damage == "checksum":
        torch.save({"w": torch.zeros(4)}, weights)  # valid file, not the one recorded
    elif damage == "other_key":
        meta.write_text(meta.read_text().replace('"seed": 0', '"seed": 9'))
    else:
        meta.unlink()
    with pytest.warns(CacheWarning, match="unusable"):
        state, _ = cached_state_dict("m", KEY, trainer(calls), root=tmp_path)
    assert calls == [1, 1] and torch.equal(state["w"], torch.arange(4.0))
    cached_state_dict("m", KEY, trainer(calls), root=tmp_path)
    assert calls == [1, 1], "the retrained model is cached again"


def test_pickled_objects_are_never_loaded(tmp_path):
    calls = []
    cached_state_dict("m", KEY, trainer(calls), root=tmp_path)
    weights = tmp_path / "m" / f"{key_digest(KEY)}.pt"

    class Evil:
        def __reduce__(self):
            return (print, ("executed",))

    torch.save({"w": Evil()}, weights)
    meta = weights.with_suffix(".json")
    import hashlib
    import json

    info = json.loads(meta.read_text())
    info["sha256"] = hashlib.sha256(weights.read_bytes()).hexdigest()
    meta.write_text(json.dumps(info))
    with pytest.warns(CacheWarning):
        cached_state_dict("m", KEY, trainer(calls), root=tmp_path)
    assert calls == [1, 1]
