"""The settling definition shared by every chapter's convergence metric, against a brute force."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from railpaper.settling import settled_index


def brute_force(ok):
    for i in range(len(ok)):
        if all(ok[i:]):
            return i
    return -1


@given(st.lists(st.booleans(), min_size=1, max_size=40))
def test_settled_index_matches_brute_force(ok):
    assert settled_index(np.array(ok)) == brute_force(ok)


def test_edge_cases():
    assert settled_index([True, True]) == 0
    assert settled_index([True, False]) == -1
    assert settled_index([False, True, True]) == 1
