"""Values a publication reports, read from a CSV, to show beside ours (``--reference``).

The CSV has columns ``task,recognizer,observability,f1`` and optionally
``ci95`` (``[low; high]``); ``f1`` reads ``mean ± std``. The paper's values
ship as ``grail_bench/paper_reported.csv``, transcribed by hand and marked as
the paper's wherever they are shown.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from grail_bench.core.errors import UserError
from grail_bench.stats.verdict import Verdict, place, welch_verdict

#: Seeds behind each of the paper's values (its tables report mean and std over 10 runs).
PAPER_SEEDS = 10
MARKS = {"inside": "=", "above": "▲", "below": "▼"}  # our mean against the paper's 95 % interval
_MEAN_STD = re.compile(r"^\s*([-+]?\d*\.?\d+)\s*(?:±\s*(\d*\.?\d+))?\s*$")


@dataclass(frozen=True)
class Reported:
    """A value a publication reports: its text, its mean and std where the text gives them, and its 95 % interval.

    Attributes:
        text: As printed, e.g. ``"0.73 ± 0.33"``.
        ci95: The appendix's 95 % interval, where it gives one.
        n: Runs behind the value (the paper's: 10 seeds).
    """

    text: str
    ci95: tuple[float, float] | None = None
    n: int = PAPER_SEEDS

    @property
    def mean_std(self) -> tuple[float, float] | None:
        """``(mean, std)`` read from :attr:`text` (std 0 when only a mean is printed), or None."""
        match = _MEAN_STD.match(self.text)
        if match is None:
            return None
        return float(match.group(1)), float(match.group(2) or 0.0)

    def place(self, mean: float) -> str | None:
        """``"inside"``, ``"above"`` or ``"below"`` the interval (None without one)."""
        return place(mean, self.ci95)

    def verdict(self, values: list[float]) -> Verdict | None:
        """Our per-seed values against this value: the two-sided Welch test (None without a mean and std)."""
        parsed = self.mean_std
        if parsed is None or len(values) < 2:
            return None
        return welch_verdict(values, parsed[0], parsed[1], self.n)

    def __str__(self) -> str:
        return self.text + (f" [{self.ci95[0]:.2f}, {self.ci95[1]:.2f}]" if self.ci95 else "")


def read_reference(path: str | Path) -> dict[tuple[str, str, float], Reported]:
    """Reported values by ``(task, recognizer, observability)``.

    Raises:
        UserError: For a file that cannot be read or a malformed row.
    """
    out = {}
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            for row in csv.DictReader(line for line in fh if not line.startswith("#")):
                try:
                    ci_text = (row.get("ci95") or "").strip().strip("[]")
                    ci = tuple(float(v) for v in ci_text.split(";")) if ci_text else None
                    if ci is not None and (len(ci) != 2 or ci[0] > ci[1]):
                        raise UserError(f"ci95 must be [low; high], got {row['ci95']!r}")
                    out[(row["task"], row["recognizer"], round(float(row["observability"]), 6))] = Reported(
                        row["f1"].strip(), ci)
                except (KeyError, ValueError, AttributeError) as exc:
                    raise UserError(f"{path}: malformed reference row {row}: {exc}") from None
    except OSError as exc:
        raise UserError(f"cannot read reference values {path}: {exc.strerror}") from None
    return out


def paper_reference_path() -> Path:
    """The paper's reported values shipped with grail-bench (see the CSV's header)."""
    return Path(str(resources.files("grail_bench").joinpath("paper_reported.csv")))
