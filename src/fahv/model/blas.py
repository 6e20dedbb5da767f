"""One BLAS thread for the model's offline computations, whatever the environment says.

A multi-threaded BLAS may sum in another order from run to run and from thread count to
thread count. The TP model's convex hull manipulation is sensitive to that: measured on
`cm_certified`, two OpenBLAS threads instead of one moved its weighting functions W_V
by 1.0e-8 and its vertices A, B by 1.3e-10 (relative). The model is therefore built on
one BLAS thread by every path (`fahv design`, `fahv verify`, a user's script that set
`OPENBLAS_NUM_THREADS` or imported numpy first), through threadpoolctl, which limits
the BLAS libraries loaded in the process (numpy's and scipy's OpenBLAS).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TypeVar

from threadpoolctl import threadpool_limits

T = TypeVar("T")


def one_blas_thread(func: Callable[..., T]) -> Callable[..., T]:
    """Run `func` with every loaded BLAS library limited to one thread.

    Parameters
    ----------
    func : callable
        The function to wrap; its arguments and result pass through unchanged.

    Returns
    -------
    callable
        The wrapped function. The limit is restored when it returns or raises.

    Examples
    --------
    >>> from threadpoolctl import threadpool_info
    >>> @one_blas_thread
    ... def blas_threads():
    ...     return {lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"}
    >>> blas_threads()
    {1}
    """

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        # threadpoolctl limits the libraries loaded when the limit is set: load scipy's
        # own OpenBLAS first (here, not at import: the nodes need no scipy.linalg)
        import scipy.linalg  # noqa: F401

        with threadpool_limits(limits=1, user_api="blas"):
            return func(*args, **kwargs)

    return wrapper
