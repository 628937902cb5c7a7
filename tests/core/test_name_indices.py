"""``plan.name_indices`` (issue 37, p10k: a search in the sorted names) against the way
it replaced: a dict of the names looked up value by value."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.core.plan import known_indices, name_indices


def _former(names, values) -> list[int]:
    index = {name: i for i, name in enumerate(names)}
    return [index.get(v, -1) for v in values]


def _word(rng) -> str:
    width = int(rng.integers(1, 12))
    return "".join(rng.choice(list("AB0-zS19"), width))


@pytest.mark.parametrize("seed", range(12))
def test_name_indices_are_the_dicts(seed):
    rng = np.random.default_rng(seed)
    names = [_word(rng) for _ in range(int(rng.integers(0, 40)))]
    if names and seed % 3 == 0:
        names += list(rng.choice(names, 5))  # names given twice: the last index
    pool = names + [_word(rng) for _ in range(10)] + ["A" * 70, "A", "AA"]
    values = [pool[int(i)] for i in rng.integers(0, len(pool), int(rng.integers(0, 300)))]
    for given in (values, np.asarray(values, dtype=str), np.asarray(values, dtype=object)):
        got = name_indices(names, given)
        assert got.dtype == np.intp
        assert got.tolist() == _former(names, values)


def test_prefixes_and_empty_inputs():
    names = ["S1", "S10", "S1-2", "R0", "O"]
    values = ["S", "S1", "S10", "S100", "S1-", "S1-2", "O", "", "R0"]
    assert name_indices(names, values).tolist() == _former(names, values)
    assert name_indices([], ["S1"]).tolist() == [-1]
    assert name_indices(names, []).tolist() == []


def test_known_indices_names_the_missing_one():
    assert known_indices(["O", "R0"], ["R0", "O"]).tolist() == [1, 0]
    with pytest.raises(KeyError, match="S7"):
        known_indices(["O", "R0"], ["R0", "S7", "S8"])
