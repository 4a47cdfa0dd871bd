"""The least-recently-used cache of built values (companion.cache)."""

from __future__ import annotations

import pytest

from companion.cache import KeyedCache


@pytest.mark.unit
def test_the_least_recently_used_entry_goes_first_and_hits_are_counted() -> None:
    cache: KeyedCache[str] = KeyedCache("test", capacity=2)
    built: list[str] = []

    def build(value: str) -> str:
        built.append(value)
        return value

    assert cache.get("a", lambda: build("a")) == "a"
    assert cache.get("b", lambda: build("b")) == "b"
    assert cache.get("a", lambda: build("a again")) == "a"  # a hit, and "a" is now the most recent
    assert cache.get("c", lambda: build("c")) == "c"  # "b" goes
    assert cache.get("b", lambda: build("b again")) == "b again"
    assert built == ["a", "b", "c", "b again"]
    assert (cache.hits, cache.misses, len(cache)) == (1, 4, 2)
    with pytest.raises(ValueError, match="capacity"):
        KeyedCache("empty", capacity=0)
