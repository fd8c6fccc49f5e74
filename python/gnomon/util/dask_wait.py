"""Futures of a Dask cluster as they complete, never waiting on a cluster with no worker left.

A Dask future waits for ever when every worker of its cluster is gone (killed, crashed, or never
started) and none comes back: ``distributed.as_completed`` then never yields again. :func:`completed`
yields the futures in the order they finish, and refuses in one line once the scheduler has listed no
worker for :data:`NO_WORKER_TIMEOUT_S` seconds in a row (a LocalCluster's nanny restarts a dead worker
within seconds; a scheduler's workers started by hand have that long to join).
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Iterator
from typing import Any

from gnomon.errors import GnomonError

NO_WORKER_TIMEOUT_S = 120.0
"""How long (seconds) a wait goes on while the scheduler lists no worker at all."""

POLL_S = 1.0
"""How often (seconds) the wait looks at the scheduler's workers while nothing completes."""


def completed(client: Any, futures: Iterable[Any], *, what: str) -> Iterator[Any]:
    """Each of ``futures`` (``distributed.Future``) once it is done, in the order they finish.

    Raises :class:`~gnomon.errors.GnomonError` naming ``what`` (e.g. "the tiles") when the scheduler has
    listed no worker for :data:`NO_WORKER_TIMEOUT_S` seconds while some are still pending."""
    from distributed import wait

    pending = list(futures)
    workerless_since: float | None = None
    while pending:
        try:
            done, not_done = wait(pending, timeout=POLL_S, return_when="FIRST_COMPLETED")
        except TimeoutError:  # distributed's TimeoutError is the builtin one
            done, not_done = set(), set(pending)
        if done:
            workerless_since = None
            pending = [f for f in pending if f in not_done]
            yield from done
            continue
        if client.scheduler_info().get("workers"):
            workerless_since = None
            continue
        now = time.monotonic()
        workerless_since = now if workerless_since is None else workerless_since
        if now - workerless_since >= NO_WORKER_TIMEOUT_S:
            raise GnomonError(f"{what}: the Dask scheduler {client.scheduler.address} has had no worker for "
                              f"{NO_WORKER_TIMEOUT_S:g} s with {len(pending)} task(s) waiting (the workers died "
                              "or never started: see their logs, start workers, or run without the cluster)")
