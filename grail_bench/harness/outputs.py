"""Per-instance outputs: what every row's metrics were computed from, kept beside the row.

For each row of every mode, an output row (keyed like it) holds the per-instance arrays the mode computed the
row's metrics from, in the order it computed them, packed as one compressed blob in a table of its own, apart from
the rows (:data:`KINDS`):

* offline (:class:`OutputRow`, table ``outputs``): per observed test trajectory its true goal ``y_true``, its
  number of observed steps ``lengths`` and the recognizer's score of every goal ``scores`` ``(N, K)``;
* online (:class:`OnlineOutputRow`, ``online_outputs``): per test trajectory its true goal ``y_true`` and its
  number of steps ``lengths``, and the scores of every prefix of every trajectory, one after the other,
  ``scores`` ``(sum of lengths, K)``;
* open set (:class:`OpenSetOutputRow`, ``open_set_outputs``): per observation its true class ``y_true`` (a known
  goal's index, or ``K`` for the held-out goal), its scores of the ``K`` known goals ``scores`` ``(N, K)``, and
  the best scores of the training observations the "none of these" threshold is calibrated on
  (``calibration``);
* zero shot (:class:`ZeroShotOutputRow`, ``zero_shot_outputs``): per observation its true goal ``y_true`` and its
  scores of every goal given at test time ``scores`` ``(N, K)``, and the indices of the goals held out of the fit
  (``held_out``).

Scores are float64, the very values the metrics were computed from, so every metric of a row but its timings is
recomputable exactly (:func:`recompute`, with the same function the run used: each mode's ``unit_metrics``).
Offline rows stored before schema 11, and the rows of the other modes before schema 12, have none.
"""

from __future__ import annotations

import io
import math
import zlib
from dataclasses import dataclass, fields
from typing import Any, Callable, ClassVar

import numpy as np

from grail_bench.harness.modes import offline, online, open_set, zero_shot
from grail_bench.harness.modes.base import Outputs
from grail_bench.harness.modes.offline import ResultRow, unit_metrics
from grail_bench.task.observation import parse_label

TABLE = "outputs"
KEY = offline.MODE.key
#: The offline row metrics recomputed from outputs (every ResultRow metric but the timings), compared exactly.
METRICS = ("accuracy", "precision", "recall", "f1", "n_observations", "n_ties", "brier", "nll", "top2",
           "mean_rank", "confusion", "reliability", "set_precision", "set_recall", "set_spread")
#: Array name -> its dtype and number of dimensions (as stored and published).
ARRAYS: dict[str, tuple[type, int]] = {"y_true": (np.int32, 1), "lengths": (np.int32, 1), "held_out": (np.int32, 1),
                                       "scores": (np.float64, 2), "calibration": (np.float64, 1)}


class _Packed:
    """The arrays of an output row: :attr:`NAMES`, as ``.npy`` arrays (no pickles) in ``data``, zlib-compressed."""

    NAMES: ClassVar[tuple[str, ...]]
    data: bytes

    def arrays(self) -> tuple[np.ndarray, ...]:
        """The arrays, in the order of :attr:`NAMES`."""
        buffer = io.BytesIO(zlib.decompress(self.data))
        return tuple(np.load(buffer, allow_pickle=False) for _ in self.NAMES)

    def named(self) -> dict[str, np.ndarray]:
        """The arrays by name."""
        return dict(zip(self.NAMES, self.arrays()))


@dataclass(frozen=True)
class OutputRow(_Packed):
    """The per-instance outputs of one offline row (keyed like it).

    ``data`` holds ``y_true`` (int32), ``lengths`` (int32) and ``scores`` (float64, observations x goals);
    ``posterior`` says whether the scores are log-likelihoods.
    """

    NAMES: ClassVar[tuple[str, ...]] = ("y_true", "lengths", "scores")
    task: str
    recognizer: str
    scorer: str
    config_hash: str
    seed: int
    observability: float
    protocol: str
    posterior: bool
    data: bytes


@dataclass(frozen=True)
class OnlineOutputRow(_Packed):
    """The per-instance outputs of one online row: ``y_true`` and ``lengths`` per trajectory, ``scores`` per prefix
    (trajectory after trajectory, ``(sum of lengths, goals)``)."""

    NAMES: ClassVar[tuple[str, ...]] = ("y_true", "lengths", "scores")
    task: str
    recognizer: str
    scorer: str
    config_hash: str
    seed: int
    protocol: str
    data: bytes


@dataclass(frozen=True)
class OpenSetOutputRow(_Packed):
    """The per-instance outputs of one open-set row: ``y_true`` (``K`` for the held-out goal), ``scores`` of the
    ``K`` known goals, and the training observations' best scores that set the threshold (``calibration``)."""

    NAMES: ClassVar[tuple[str, ...]] = ("y_true", "scores", "calibration")
    task: str
    recognizer: str
    scorer: str
    config_hash: str
    seed: int
    observability: float
    protocol: str
    data: bytes


@dataclass(frozen=True)
class ZeroShotOutputRow(_Packed):
    """The per-instance outputs of one zero-shot row: ``y_true``, ``scores`` of every goal, and the indices of the
    goals held out of the fit (``held_out``)."""

    NAMES: ClassVar[tuple[str, ...]] = ("y_true", "scores", "held_out")
    task: str
    recognizer: str
    scorer: str
    config_hash: str
    seed: int
    observability: float
    protocol: str
    data: bytes


def arrays_of(names: tuple[str, ...], values: dict[str, Any]) -> dict[str, np.ndarray]:
    """``values``' arrays ``names`` in their stored dtypes (:data:`ARRAYS`).

    Raises:
        ValueError: For a value that is not an array of its name's dimensions (``scores``: a rectangular matrix).
    """
    out = {}
    for name in names:
        dtype, ndim = ARRAYS[name]
        try:
            out[name] = np.asarray(values[name], dtype=dtype)
        except (TypeError, ValueError, OverflowError) as exc:
            raise ValueError(f"{name} is not an array of {np.dtype(dtype).name}: {exc}") from None
        if out[name].ndim != ndim:
            raise ValueError(f"{name} must be an array of {ndim} dimension(s), not {out[name].ndim}")
    return out


def pack_arrays(names: tuple[str, ...], values: dict[str, Any]) -> bytes:
    """The ``data`` of an output row holding ``names`` (the same arrays give the same bytes).

    Raises:
        ValueError: As :func:`arrays_of`.
    """
    buffer = io.BytesIO()
    for array in arrays_of(names, values).values():
        np.save(buffer, array, allow_pickle=False)
    return zlib.compress(buffer.getvalue(), 6)


def pack(y_true: Any, lengths: Any, scores: Any) -> bytes:
    """The ``data`` of an :class:`OutputRow` (the same arrays give the same bytes)."""
    return pack_arrays(OutputRow.NAMES, {"y_true": y_true, "lengths": lengths,
                                         "scores": np.asarray(scores, dtype=np.float64).reshape(len(y_true), -1)})


def recompute(outputs: OutputRow) -> dict[str, Any]:
    """An offline row's metrics (:data:`METRICS`) recomputed from its outputs."""
    y_true, lengths, scores = outputs.arrays()
    return unit_metrics([int(y) for y in y_true], list(scores), [int(n) for n in lengths], bool(outputs.posterior),
                        scores.shape[1])


def _recompute_online(outputs: OnlineOutputRow) -> dict[str, Any]:
    y_true, lengths, scores = outputs.arrays()
    scored = np.split(scores, np.cumsum(lengths)[:-1])
    return online.unit_metrics(scored, [int(y) for y in y_true], scores.shape[1], parse_label(outputs.protocol).rounding)


def _recompute_open_set(outputs: OpenSetOutputRow) -> dict[str, Any]:
    y_true, scores, calibration = outputs.arrays()
    return open_set.unit_metrics(scores, y_true.astype(np.int64), calibration)


def _recompute_zero_shot(outputs: ZeroShotOutputRow) -> dict[str, Any]:
    y_true, scores, held_out = outputs.arrays()
    return zero_shot.unit_metrics(y_true, scores, held_out)


def _consistent_offline(a: dict[str, np.ndarray]) -> bool:
    return len(a["y_true"]) == len(a["lengths"]) == len(a["scores"])


def _consistent_online(a: dict[str, np.ndarray]) -> bool:
    return (len(a["y_true"]) == len(a["lengths"]) > 0 and int(a["lengths"].min()) > 0
            and int(a["lengths"].sum()) == len(a["scores"]))


def _consistent_open_set(a: dict[str, np.ndarray]) -> bool:
    n_known = a["scores"].shape[1]
    return (len(a["y_true"]) == len(a["scores"]) > 0 and len(a["calibration"]) > 0
            and bool(np.all((a["y_true"] >= 0) & (a["y_true"] <= n_known))))


def _consistent_zero_shot(a: dict[str, np.ndarray]) -> bool:
    n_goals = a["scores"].shape[1]
    return (len(a["y_true"]) == len(a["scores"]) > 0 and 0 < len(a["held_out"]) < n_goals
            and bool(np.all((a["y_true"] >= 0) & (a["y_true"] < n_goals)))
            and bool(np.all((a["held_out"] >= 0) & (a["held_out"] < n_goals))))


@dataclass(frozen=True)
class Kind:
    """The per-instance outputs of one mode's rows.

    Attributes:
        name: Its table, and its kind in the published format (``<domain>/<name>.jsonl``).
        mode: The rows' mode name.
        of: The row type whose outputs these are.
        row: The output row type.
        key: The fields identifying an output row (its row's key).
        metrics: The row fields recomputed from the outputs, compared exactly.
        recompute: ``recompute(output row) -> {metric: value}``.
        consistent: Whether arrays read from a published line fit together (lengths, indices).
        shapes: What :attr:`consistent` requires, said in words.
        f1: The metric whose largest gap a run again reports (``results verify``): the rows' F1 (online: the area
            under the F1 curve).
    """

    name: str
    mode: str
    of: type
    row: type
    key: tuple[str, ...]
    metrics: tuple[str, ...]
    recompute: Callable[[Any], dict[str, Any]]
    consistent: Callable[[dict[str, np.ndarray]], bool]
    shapes: str
    f1: str = "f1"

    def output_row(self, outputs: Outputs) -> Any:
        """The stored form of a run's :class:`~grail_bench.harness.modes.base.Outputs` of this kind."""
        names = {f.name for f in fields(self.row)}
        values = {k: getattr(outputs.row, k) for k in self.key}
        if "posterior" in names:
            values["posterior"] = bool(outputs.posterior)
        return self.row(**values, data=pack_arrays(self.row.NAMES, outputs.arrays))


#: Output kind name -> its kind, one per mode.
KINDS: dict[str, Kind] = {k.name: k for k in (
    Kind(TABLE, "offline", ResultRow, OutputRow, KEY, METRICS, recompute, _consistent_offline,
         "y_true, lengths and scores must hold one entry per observation"),
    Kind("online_outputs", "online", online.OnlineRow, OnlineOutputRow, online.MODE.key,
         ("n_trajectories", "convergence", "never", "step_accuracy", "f1_auc", "curve", "n_ties"),
         _recompute_online, _consistent_online,
         "y_true and lengths must hold one entry per trajectory, each length at least 1, and scores one row per "
         "prefix (the sum of lengths)", f1="f1_auc"),
    Kind("open_set_outputs", "open-set", open_set.OpenSetRow, OpenSetOutputRow, open_set.MODE.key,
         ("auroc", "f1", "accuracy", "unknown_recall", "false_alarm", "threshold", "n_observations", "n_ties"),
         _recompute_open_set, _consistent_open_set,
         "y_true and scores must hold one entry per observation, y_true in 0..K (K: the held-out goal, with K "
         "the known goals scored), and calibration at least one score"),
    Kind("zero_shot_outputs", "zero-shot", zero_shot.ZeroShotRow, ZeroShotOutputRow, zero_shot.MODE.key,
         ("n_goals", "f1", "accuracy", "f1_held_out", "f1_trained", "accuracy_held_out", "accuracy_trained",
          "n_observations", "n_ties"),
         _recompute_zero_shot, _consistent_zero_shot,
         "y_true and scores must hold one entry per observation, y_true and held_out index the K goals scored, "
         "and some but not all goals held out"),
)}
#: The output row types.
ROW_TYPES: tuple[type, ...] = tuple(k.row for k in KINDS.values())
_BY_OF = {k.of: k for k in KINDS.values()}
_BY_ROW = {k.row: k for k in KINDS.values()}


def output_kind(row: Any) -> Kind:
    """The output kind of an output row, or of the row (of any mode) it is the outputs of."""
    return _BY_ROW.get(type(row)) or _BY_OF[type(row)]


def output_row(outputs: Outputs) -> Any:
    """The stored form of a run's :class:`~grail_bench.harness.modes.base.Outputs` (of any mode)."""
    return output_kind(outputs.row).output_row(outputs)


def disagreements(row: Any, outputs: Any) -> list[str]:
    """The metrics a row states that its outputs do not give (empty when every one agrees exactly)."""
    kind = output_kind(outputs)
    again = kind.recompute(outputs)
    return [name for name in kind.metrics if not _same(getattr(row, name), again[name])]


def differing(row: Any, other: Any) -> list[str]:
    """The recomputable metrics (its output kind's) on which two rows of one mode differ (empty: all agree
    exactly, NaN agreeing with NaN)."""
    return [name for name in output_kind(row).metrics if not _same(getattr(row, name), getattr(other, name))]


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    return a == b
