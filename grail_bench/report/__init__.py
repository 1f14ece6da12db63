"""The report layer: the leaderboard model computed once from stored rows, and everything that draws it.

* :mod:`.boards`: the paper-style table model; :mod:`.reference`: values a publication reports.
* :mod:`.leaderboard`: records, boards, ceilings and the other modes' studies, built once.
* :mod:`.text` (terminal and Markdown), :mod:`.html` (the web page), :mod:`.plots` (every figure).
* :mod:`.reproduce`: profiles and the outputs of ``grail-bench reproduce``.
"""
