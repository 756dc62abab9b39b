"""The one-thread context: numba and OpenBLAS on one thread inside, restored after."""

import numba

from railpaper.threads import _openblas_handles, one_thread


def test_one_thread_restores_the_thread_counts():
    """From two threads (numba's and OpenBLAS's; the test session runs OpenBLAS on one, so it
    is set to two here first) to one inside, and back."""
    handles = _openblas_handles()
    outside = [get() for _, get in handles]
    for setter, _ in handles:
        setter(2)
    try:
        before = numba.get_num_threads(), [get() for _, get in handles]
        assert before[1] == [2] * len(handles)
        with one_thread():
            assert numba.get_num_threads() == 1
            assert all(get() == 1 for _, get in handles)
        assert (numba.get_num_threads(), [get() for _, get in handles]) == before
    finally:
        for (setter, _), threads in zip(handles, outside):
            setter(threads)


def test_one_thread_restores_after_an_error():
    before = numba.get_num_threads()
    try:
        with one_thread():
            raise RuntimeError("inside")
    except RuntimeError:
        pass
    assert numba.get_num_threads() == before
