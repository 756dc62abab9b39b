"""The one-thread context: numba and OpenBLAS on one thread inside, restored after."""

import numba

from railpaper.threads import _openblas_handles, one_thread


def test_one_thread_restores_the_thread_counts():
    before = numba.get_num_threads(), [get() for _, get in _openblas_handles()]
    with one_thread():
        assert numba.get_num_threads() == 1
        assert all(get() == 1 for _, get in _openblas_handles())
    assert (numba.get_num_threads(), [get() for _, get in _openblas_handles()]) == before


def test_one_thread_restores_after_an_error():
    before = numba.get_num_threads()
    try:
        with one_thread():
            raise RuntimeError("inside")
    except RuntimeError:
        pass
    assert numba.get_num_threads() == before
