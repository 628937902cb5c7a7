"""``records._distinct_pairs`` (issue 37, p10k: the groups' steps and balls sorted, not put
in a dict one by one) against the dict ``check_groups`` built before."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.io.records import Records, _distinct_pairs, check_groups


def _former(first, second) -> bool:
    groups: dict[tuple[str, str], int] = {}
    for key in zip(first.tolist(), second.tolist(), strict=True):
        groups[key] = groups.get(key, 0) + 1
    return all(count == 1 for count in groups.values())


@pytest.mark.parametrize("seed", range(20))
def test_distinct_pairs_are_the_dicts(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(0, 200))
    words = ["S1", "S10", "S1-2", "B1", "B", "O", "R0", "a" * 30, "S", "1S"]
    first = np.array([words[i] for i in rng.integers(0, len(words), n)], dtype=str)
    second = np.array([words[i] for i in rng.integers(0, 3 if seed % 2 else 10, n)], dtype=str)
    if seed % 4 == 0:  # pairs made distinct: the common case
        first = np.array([f"T{i}" for i in range(n)], dtype=str)
    assert _distinct_pairs(first, second) == _former(first, second)


def test_equal_parts_of_different_pairs_are_distinct():
    # a step repeated with another ball and a ball with another step: no pair repeated
    assert _distinct_pairs(np.array(["S1", "S1", "S2"]), np.array(["B1", "B2", "B1"]))
    assert not _distinct_pairs(np.array(["S1", "S2", "S1"]), np.array(["B1", "B1", "B1"]))
    # joined they would be one text: S1 + B12 and S1B + 12
    assert _distinct_pairs(np.array(["S1", "S1B"]), np.array(["B12", "12"]))


def test_a_text_with_trailing_nul_is_left_to_the_dict():
    # numpy compares "B1\0" as "B1": not distinct here, the dict then decides (distinct)
    first, second = np.array(["S1", "S1"]), np.array(["B1", "B1\x00"], dtype=object)
    assert not _distinct_pairs(first, second.astype(str))
    assert _former(first, second)


def _points(labels, balls) -> Records:
    n = len(labels)
    return Records(
        path="p.csv",
        kind="points",
        label=np.array(labels),
        ball=np.array(balls),
        xyz_mm=np.zeros((n, 3)),
        time_s=np.arange(n, dtype=float),
        time_kind="seconds",
        line=np.arange(2, n + 2),
    )


def test_check_groups_still_refuses_a_ball_probed_twice():
    ok = _points(["S1", "S1", "S1", "S2"], ["B1", "B1", "B2", "B1"])
    assert check_groups(ok) is ok
    with pytest.raises(Exception, match="p.csv:5: field 'ball': step S1 ball B1 probed twice"):
        check_groups(_points(["S1", "S1", "S1", "S1"], ["B1", "B1", "B2", "B1"]))
