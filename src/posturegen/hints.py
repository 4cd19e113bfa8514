"""Close names for a mistyped one: what an error about an unknown frame, patch, surface, robot
or key suggests instead (``did you mean right_hand_palm_link?``).

Candidates are the names that contain the given one (or that it contains), and difflib's close
matches (similarity >= 0.6); the containing names first, each group ranked by similarity.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable

MAX_HINTS = 3
CUTOFF = 0.6  # difflib's similarity ratio
MIN_SUBSTRING = 3  # shorter names are not looked up as substrings


def close_names(name: str, known: Iterable[str], n: int = MAX_HINTS) -> list[str]:
    """Up to ``n`` known names close to ``name`` (none equal to it)."""
    name = str(name)
    known = list(dict.fromkeys(str(k) for k in known if str(k) != name))
    if not known:  # nothing to suggest (difflib refuses to look for 0 matches)
        return []
    low = name.lower()

    def ratio(k: str) -> float:
        return difflib.SequenceMatcher(None, low, k.lower()).ratio()

    contains = []
    if len(low) >= MIN_SUBSTRING:
        contains = [
            k for k in known if low in k.lower() or (len(k) >= MIN_SUBSTRING and k.lower() in low)
        ]
    close = difflib.get_close_matches(low, [k.lower() for k in known], n=len(known), cutoff=CUTOFF)
    by_lower = {k.lower(): k for k in known}
    similar = [by_lower[c] for c in close]
    ranked = sorted(contains, key=lambda k: -ratio(k)) + [k for k in similar if k not in contains]
    return ranked[:n]


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """``did you mean a, b or c?`` for the close names, "" when there are none."""
    names = close_names(name, known)
    if not names:
        return ""
    if len(names) == 1:
        return f"did you mean {names[0]}?"
    return f"did you mean {', '.join(names[:-1])} or {names[-1]}?"


def with_hint(name: str, known: Iterable[str], fix: str) -> str:
    """An error's fix, led by the close names when there are some."""
    hint = did_you_mean(name, known)
    return f"{hint} {fix}" if hint else fix
