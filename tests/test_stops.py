"""Tests for flrjax.stops: the signals that stop a run cleanly (train's use of them:
tests/test_runner.py)."""

import signal
import threading

from flrjax import stops


def test_stop_signals_are_caught_once_then_left_to_their_default_and_put_back():
    before = {s: signal.getsignal(s) for s in stops.STOP_SIGNALS}
    with stops.stop_on_signals() as received:
        signal.pthread_kill(threading.main_thread().ident, signal.SIGTERM)
        assert received == [signal.SIGTERM]
        # a second signal would take the default action: end the process at once
        assert all(signal.getsignal(s) == signal.SIG_DFL for s in stops.STOP_SIGNALS)
    assert {s: signal.getsignal(s) for s in stops.STOP_SIGNALS} == before
    seen = []

    def elsewhere():  # only the main thread can set handlers; another leaves them alone
        with stops.stop_on_signals() as r:
            seen.append((r, signal.getsignal(signal.SIGINT)))

    t = threading.Thread(target=elsewhere)
    t.start()
    t.join()
    assert seen == [([], before[signal.SIGINT])]
