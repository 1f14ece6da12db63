"""Per-instance outputs: what every offline row's metrics were computed from, kept beside the row.

For each offline row (one unit, level and scorer) an :class:`OutputRow` holds, per observed test trajectory, its
true goal, its number of observed steps and the recognizer's score of every goal (float64, the very values the
metrics were computed from), packed as one compressed blob in the store's ``outputs`` table, apart from
the rows. Every offline metric but the timings is recomputable from it (:func:`recompute`, the same
:func:`grail_bench.harness.modes.offline.unit_metrics` the run used). Rows stored before schema 11, and the
rows of the other modes, have none.
"""

from __future__ import annotations

import io
import math
import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from grail_bench.harness.modes.base import Outputs
from grail_bench.harness.modes.offline import MODE as OFFLINE
from grail_bench.harness.modes.offline import ResultRow, unit_metrics

TABLE = "outputs"
KEY = OFFLINE.key
#: The row metrics recomputed from outputs (every ResultRow metric but the timings), compared exactly.
METRICS = ("accuracy", "precision", "recall", "f1", "n_observations", "n_ties", "brier", "nll", "top2",
           "mean_rank", "confusion", "reliability", "set_precision", "set_recall", "set_spread")


@dataclass(frozen=True)
class OutputRow:
    """The per-instance outputs of one offline row (keyed like it).

    ``data`` is three ``.npy`` arrays (no pickles), zlib-compressed: ``y_true`` (int32), ``lengths`` (int32) and
    ``scores`` (float64, observations x goals); ``posterior`` says whether the scores are log-likelihoods.
    """

    task: str
    recognizer: str
    scorer: str
    config_hash: str
    seed: int
    observability: float
    protocol: str
    posterior: bool
    data: bytes

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(y_true, lengths, scores)``."""
        buffer = io.BytesIO(zlib.decompress(self.data))
        y_true, lengths, scores = (np.load(buffer, allow_pickle=False) for _ in range(3))
        return y_true, lengths, scores


def pack(y_true: Any, lengths: Any, scores: Any) -> bytes:
    """The ``data`` of an :class:`OutputRow` (the same arrays give the same bytes)."""
    buffer = io.BytesIO()
    for array in (np.asarray(y_true, dtype=np.int32), np.asarray(lengths, dtype=np.int32),
                  np.asarray(scores, dtype=np.float64).reshape(len(y_true), -1)):
        np.save(buffer, array, allow_pickle=False)
    return zlib.compress(buffer.getvalue(), 6)


def output_row(outputs: Outputs) -> OutputRow:
    """The stored form of a run's :class:`~grail_bench.harness.modes.base.Outputs`."""
    r = outputs.row
    return OutputRow(r.task, r.recognizer, r.scorer, r.config_hash, r.seed, r.observability, r.protocol,
                     bool(outputs.posterior), pack(outputs.y_true, outputs.lengths, outputs.scored))


def recompute(outputs: OutputRow) -> dict[str, Any]:
    """A row's metrics (:data:`METRICS`) recomputed from its outputs."""
    y_true, lengths, scores = outputs.arrays()
    return unit_metrics([int(y) for y in y_true], list(scores), [int(n) for n in lengths], bool(outputs.posterior),
                        scores.shape[1])


def disagreements(row: ResultRow, outputs: OutputRow) -> list[str]:
    """The metrics a row states that its outputs do not give (empty when every one agrees exactly)."""
    again = recompute(outputs)
    return [name for name in METRICS if not _same(getattr(row, name), again[name])]


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    return a == b
