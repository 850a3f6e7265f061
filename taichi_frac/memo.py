"""Bounded memos of what a process made once: the oldest entries go first past a limit."""

from __future__ import annotations


def remember(memo: dict, key, value, kept: int) -> None:
    """``memo[key] = value``, as its newest entry, the oldest dropped past ``kept`` entries."""
    memo.pop(key, None)
    while len(memo) >= kept:
        del memo[next(iter(memo))]
    memo[key] = value


def made_for(memo: dict, arrays: tuple, key, make, kept: int):
    """``make()``, made once for ``arrays`` (the same objects, not equal ones: a memo keyed
    by their contents would hash them at every ask) and ``key``, kept while it is among the
    ``kept`` most recently asked. The memo holds the arrays, so their ids are not reused by
    other objects while their entry lives."""
    entry = (tuple(map(id, arrays)), key)
    found = memo.get(entry)
    if found is not None and all(held is array for held, array in zip(found[0], arrays)):
        value = found[1]
    else:
        value = make()
    remember(memo, entry, (arrays, value), kept)
    return value
