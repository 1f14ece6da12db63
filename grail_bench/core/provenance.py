"""Where a result came from: command line, code commit, Python, machine and time.

Stored with every row a sweep writes (``ResultRow.provenance``) and in each
reproduction's ``manifest.json``, so a number on the leaderboard can be traced
to the run that produced it.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Sequence


def git_commit() -> str | None:
    """The commit of the grail-bench checkout, when it is one, suffixed ``+dirty`` when tracked files differ from it."""
    root = Path(__file__).resolve().parent.parent
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=10)
        if head.returncode != 0 or not head.stdout.strip():
            return None
        dirty = subprocess.run(["git", "-C", str(root), "diff", "--quiet", "HEAD", "--", "grail_bench"],
                               capture_output=True, timeout=10).returncode == 1
    except (OSError, subprocess.SubprocessError):
        return None
    return head.stdout.strip() + ("+dirty" if dirty else "")


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``; the platform's processor string elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def now() -> str:
    """The current UTC time, ISO 8601 to the second."""
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def machine() -> dict[str, Any]:
    """Python, platform, CPU model and core count."""
    return {"python": sys.version.split()[0], "platform": platform.platform(), "cpu": cpu_model(),
            "cores": os.cpu_count()}


def stamp(argv: Sequence[str] | None = None) -> str:
    """JSON of the command line (``sys.argv`` by default), commit, machine and start time of a run."""
    command = list(sys.argv if argv is None else argv)
    if command:
        command[0] = Path(command[0]).name
    return json.dumps({"command": command, "git_commit": git_commit(), **machine(), "date": now()}, sort_keys=True)


def model_versions() -> list[str]:
    """The versions of the packages a trained model depends on, for cache keys: a model cached under other versions
    of SB3 (its policies, rollouts and PPO) or torch is trained again."""
    from importlib.metadata import version

    return [version("stable-baselines3"), version("torch")]


def package_versions(names: Sequence[str] = ("grail-bench", "gymnasium", "stable-baselines3", "minigrid", "torch",
                                              "numpy")) -> str:
    """JSON of the installed versions of the packages that shape a result."""
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for name in names:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = None
    return json.dumps(out, sort_keys=True)
