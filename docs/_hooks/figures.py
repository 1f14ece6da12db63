"""MkDocs hook: the published figures (``leaderboard/**/*.png``) become files of the site.

Each is served at ``results/figures/<path under leaderboard/>``, so the Results pages show the figures the
scripts wrote without a copy of them in ``docs/``. The web leaderboard's own figures (``leaderboard/site/``)
stay with it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from mkdocs.structure.files import File, Files

PREFIX = "results/figures"


def on_files(files: Files, config: Any) -> Files:
    """Add every published PNG figure under ``results/figures/``."""
    leaderboard = Path(config["config_file_path"]).parent / "leaderboard"
    for figure in sorted(leaderboard.rglob("*.png")):
        relative = figure.relative_to(leaderboard)
        if relative.parts[0] != "site":
            files.append(File.generated(config, f"{PREFIX}/{relative.as_posix()}", abs_src_path=str(figure)))
    return files
