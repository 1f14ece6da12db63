"""MkDocs hook: the Sphinx roles of docstrings (``:class:`~a.b.C```) read as code on the generated pages.

The code's docstrings name objects with Sphinx roles (``help()`` and editors show them as they are);
mkdocstrings renders them as the role's name followed by code (``:class:<code>~a.b.C</code>``). This hook
drops the role and, as Sphinx does for a leading ``~``, keeps the last part of the name.
"""

from __future__ import annotations

import re
from typing import Any

ROLE = re.compile(r":(?:py:)?(?:class|func|meth|attr|mod|data|exc|obj|const):<code>(?P<tilde>~?)(?P<name>[^<]+)</code>")


def _code(match: re.Match[str]) -> str:
    name = match["name"].rsplit(".", 1)[-1] if match["tilde"] else match["name"]
    return f"<code>{name}</code>"


def on_page_content(html: str, page: Any, config: Any, files: Any) -> str:
    """Replace every role before code with the code alone."""
    return ROLE.sub(_code, html)
