"""Latest-wins scheduling: the render worker runs the newest job only, a
running job learns it was superseded, and the outbox keeps one frame waiting."""

import threading

from clvis.view import LatestWins, Outbox


def test_waiting_jobs_are_replaced_not_queued():
    gate = threading.Event()
    started = threading.Event()
    ran = []

    def blocker(superseded):
        started.set()
        gate.wait(5)
        ran.append("first")

    w = LatestWins()
    try:
        w.submit(blocker)
        assert started.wait(5)
        for i in range(10):  # a burst of mouse events while a frame renders
            w.submit(lambda s, i=i: ran.append(i))
        gate.set()
        assert w.wait_idle(5)
        assert ran == ["first", 9]  # the newest only, once
        assert w.dropped == 9
    finally:
        w.close()


def test_a_running_job_sees_it_was_superseded():
    started, gate = threading.Event(), threading.Event()
    seen = []

    def progressive(superseded):
        seen.append(superseded())
        started.set()
        gate.wait(5)
        seen.append(superseded())  # a pass loop checks here and stops

    w = LatestWins()
    try:
        w.submit(progressive)
        assert started.wait(5)
        w.submit(lambda s: seen.append("newer"))
        gate.set()
        assert w.wait_idle(5)
        assert seen == [False, True, "newer"]
    finally:
        w.close()


def test_the_worker_survives_a_failing_job():
    errors = []
    w = LatestWins(on_error=errors.append)
    try:
        w.submit(lambda s: 1 / 0)
        assert w.wait_idle(5)
        done = []
        w.submit(lambda s: done.append(True))
        assert w.wait_idle(5)
        assert done == [True] and len(errors) == 1 and isinstance(errors[0], ZeroDivisionError)
    finally:
        w.close()


def test_submit_after_close_is_refused():
    w = LatestWins()
    w.close()
    try:
        w.submit(lambda s: None)
    except RuntimeError as e:
        assert "closed" in str(e)
    else:
        raise AssertionError("submit after close must fail")


def test_outbox_sends_one_at_a_time_latest_wins():
    sent = []
    box = Outbox(sent.append)
    box.put("a")  # nothing in flight: sent at once
    box.put("b")
    box.put("c")  # replaces b, which never goes
    box.put("d")  # replaces c
    assert sent == ["a"] and box.dropped == 2
    box.done()  # a arrived: the newest waiting frame goes
    assert sent == ["a", "d"]
    box.done()  # d arrived, nothing waits
    box.put("e")
    assert sent == ["a", "d", "e"] and box.sent == 3


def test_keys_take_turns_and_each_keeps_its_newest_job():
    """Two pages' views: each key's newest job runs; a job that is an
    iterator (a progressive render's frames) is stepped one item a turn, so
    one key's passes do not hold the other's back."""
    gate = threading.Event()
    steps = []

    def frames(name, n):
        def job(superseded):
            for i in range(n):
                gate.wait(5)
                steps.append((name, i))
                yield
                if superseded():
                    return

        return job

    w = LatestWins()
    try:
        w.submit(frames("a", 4), key="a")
        w.submit(frames("b", 2), key="b")
        w.submit(frames("b-newer", 2), key="b")  # replaces b's waiting job
        gate.set()
        assert w.wait_idle(5)
        assert steps == [("a", 0), ("b-newer", 0), ("a", 1), ("b-newer", 1), ("a", 2), ("a", 3)]
        assert w.dropped == 1 and not w._latest
    finally:
        w.close()


def test_a_cancelled_key_stops_and_its_iterator_is_closed():
    started, gate = threading.Event(), threading.Event()
    closed = []

    def job(superseded):
        try:
            for _ in range(100):
                started.set()
                gate.wait(5)
                yield
        finally:
            closed.append(superseded())

    w = LatestWins()
    try:
        w.submit(job, key="page")
        assert started.wait(5)
        w.cancel("page")  # the page went away
        gate.set()
        assert w.wait_idle(5)
        assert closed == [True] and not w._latest and not w._ready
    finally:
        w.close()
