"""A producer thread and its consumer: items handed over through a bounded queue, in order; an exception
raised on the producer's thread is raised again on the consumer's, and the consumer leaving stops the
producer (frames decoded ahead of the tracker, frames registered ahead of it)."""

from __future__ import annotations

import queue
import threading
from collections.abc import Generator, Iterable, Iterator
from typing import TypeVar

__all__ = ["ahead", "received"]

T = TypeVar("T")


def received(out: queue.Queue[object], done: object) -> Iterator[object]:
    """The items a producer thread puts on ``out``, in order, until it puts ``done``; an exception it puts
    (its own, forwarded) is raised here."""
    while True:
        item = out.get()
        if item is done:
            return
        if isinstance(item, BaseException):
            raise item
        yield item


def ahead(items: Iterable[T], size: int, name: str, join_timeout: float | None = None) -> Generator[T, None, None]:
    """``items`` iterated on a thread of its own (named ``name``), at most ``size`` items ahead of the
    consumer, in order. An exception there is raised here; closing this iterator (leaving a ``for`` over
    it, or its ``close()``) stops the thread, which finishes the item it is on, and joins it (waiting
    ``join_timeout`` seconds at most; None: until it ends)."""
    out: queue.Queue[object] = queue.Queue(maxsize=size)
    stop = threading.Event()
    done = object()

    def put(item: object) -> bool:
        while not stop.is_set():
            try:
                out.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        try:
            for item in items:
                if stop.is_set() or not put(item):
                    return
            put(done)
        except BaseException as exc:  # forwarded to the consumer, raised there
            put(exc)

    worker = threading.Thread(target=produce, name=name, daemon=True)
    worker.start()
    try:
        yield from received(out, done)  # type: ignore[misc]
    finally:
        stop.set()
        worker.join(timeout=join_timeout)
