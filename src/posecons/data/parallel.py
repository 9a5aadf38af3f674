"""Work spread over forked processes (synthetic rendering, frame caching)."""

from __future__ import annotations

import multiprocessing
import signal
from collections.abc import Callable, Iterable
from typing import Any


def fork_map(func: Callable[[Any], Any], items: Iterable[Any], workers: int) -> list[Any]:
    """``[func(x) for x in items]``, in ``workers`` forked processes where the platform allows it
    (they inherit the parent's module state; nothing but the items and results is pickled)."""
    items = list(items)
    if workers > 1 and len(items) > 1 and "fork" in multiprocessing.get_all_start_methods():
        # Ctrl-C reaches the whole process group: the workers are forked with it blocked (a worker
        # that died of it would hang the pool), the parent receives it once they exist and stops them.
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            pool = multiprocessing.get_context("fork").Pool(workers)
        finally:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        with pool:
            return pool.map(func, items, chunksize=max(1, len(items) // (4 * workers)))
    return [func(x) for x in items]
