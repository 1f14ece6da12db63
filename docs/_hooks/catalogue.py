"""MkDocs hook: the task catalogue page, built from ``tasks/*.toml`` by the package's own card loader.

A page holding the marker ``<!-- task-catalogue -->`` gets, in its place, one section per card file with a
table of the tasks that card defines (IDs, domain, regime, goals, demonstrations, levels and protocol).
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

from grail_bench.task.cards import VERSIONS_FILE, load_cards
from grail_bench.task.observation import level_text

MARKER = "<!-- task-catalogue -->"


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _goal(goal: Any) -> str:
    return "(" + ", ".join(str(v) for v in goal) + ")" if isinstance(goal, (tuple, list)) else str(goal)


def catalogue(cards_dir: Path) -> str:
    """Markdown for every task the cards in ``cards_dir`` define, grouped by card file."""
    cards = sorted(p for p in cards_dir.glob("*.toml") if p.name != VERSIONS_FILE)  # the versions table is no card
    by_card: dict[str, list[Any]] = defaultdict(list)
    for task in load_cards(cards):
        by_card[Path(task.source).name].append(task)
    total = sum(len(tasks) for tasks in by_card.values())
    out = [f"{total} tasks from {len(cards)} cards.", ""]
    for name in sorted(by_card):
        tasks = by_card[name]
        out += [f"## `{name}`", "", f"{len(tasks)} tasks.", "",
                "| ID | domain | regime | goals | demos/goal (train/test) | observed | protocol |",
                "|---|---|---|---|---|---|---|"]
        for t in tasks:
            goals = " ".join(_goal(g) for g in t.goals)
            levels = ", ".join(level_text(p) for p in t.observability)
            out.append(f"| `{t.id}` | {t.domain} | {t.regime} | {_cell(goals)} | "
                       f"{t.n_demos} ({t.n_train}/{t.n_demos - t.n_train}) | {levels} | {t.protocol_label} |")
        out.append("")
    return "\n".join(out)


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    """Replace the catalogue marker with the generated tables."""
    if MARKER not in markdown:
        return markdown
    root = Path(config["config_file_path"]).parent
    return markdown.replace(MARKER, catalogue(root / "tasks"))
