"""The recorders' background worker: items handled in order off the caller's thread; errors surface once."""

import threading

import pytest

from embodied_adhoc.record.worker import BackgroundWorker


def test_items_are_handled_in_order_on_another_thread():
    seen, threads = [], set()

    def handle(item):
        seen.append(item)
        threads.add(threading.current_thread().name)

    worker = BackgroundWorker(handle, "test worker", max_queued=2)
    for item in range(50):
        worker.submit(item)
    worker.close()
    assert seen == list(range(50)) and threads == {"test worker"}
    with pytest.raises(RuntimeError, match="after close"):
        worker.submit(1)


def test_an_error_stops_the_worker_and_is_raised_once():
    def handle(item):
        if item == 3:
            raise ValueError("bad item 3")

    worker = BackgroundWorker(handle, "failing worker", max_queued=1)
    with pytest.raises(RuntimeError, match="failing worker failed: bad item 3"):
        for item in range(100):  # a full queue must not block once the worker has stopped
            worker.submit(item)
    worker.close()  # already reported
    assert worker.failed


def test_finish_runs_last_on_the_worker_thread_after_an_error_too():
    for fail in (False, True):
        events = []

        def handle(item, fail=fail, events=events):
            events.append(("item", threading.current_thread().name))
            if fail:
                raise ValueError("broken")

        def finish(events=events):
            events.append(("finish", threading.current_thread().name))

        worker = BackgroundWorker(handle, "finishing worker", max_queued=4, finish=finish)
        worker.submit(1)
        if fail:
            with pytest.raises(RuntimeError, match="broken"):
                worker.close()
        else:
            worker.close()
        assert events == [("item", "finishing worker"), ("finish", "finishing worker")]
