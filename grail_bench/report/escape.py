"""The one rule for names (tasks, recognizers, scorers, labels) reaching a document: one function per format.

A name is data, never markup. :func:`md` writes it into Markdown (a table cell,
a heading, a sentence) so that every renderer (GitHub, CommonMark, a plain
text viewer) shows the name as it is and nothing in it acts: ``<`` and ``>``
become ``&lt;`` and ``&gt;`` (no HTML element, comment or script), ``&`` stays
``&`` unless it would start an entity (``&lt;`` in a name is written
``&amp;lt;``), ``|`` cannot end a cell, ``*``, `````, ``[`` and ``]`` cannot
start emphasis, code or a link, and a line break cannot end a table row.
:func:`html` writes it into HTML (text or an attribute value): the escaping
Jinja's autoescape applies to every value the site's templates show
(:mod:`grail_bench.report.html`), for HTML built outside a template.
"""

from __future__ import annotations

import re

import markupsafe

__all__ = ["html", "md"]

#: An ``&`` that would start a character reference (``&lt;``, ``&#60;``, ``&#x3c;``).
_ENTITY = re.compile(r"&(?=#?[0-9A-Za-z]+;)")
#: Markdown punctuation backslash-escaped inside text (CommonMark escapes any ASCII punctuation this way).
_PUNCTUATION = re.compile(r"([\\`*\[\]|])")


def md(text: object) -> str:
    """``text`` (a name or label) as Markdown that shows it as it is (see the module docstring)."""
    out = _ENTITY.sub("&amp;", str(text))
    out = out.replace("<", "&lt;").replace(">", "&gt;")
    out = _PUNCTUATION.sub(r"\\\1", out)
    return " ".join(out.splitlines()) if "\n" in out or "\r" in out else out


def html(text: object) -> str:
    """``text`` as HTML text or a quoted attribute value (``<``, ``>``, ``&``, ``"`` and ``'`` escaped), as the
    site's templates escape every value."""
    return str(markupsafe.escape(str(text)))
