"""`quaddance.children.HelperProcess`: calls, failures, and a helper that ends on its own."""

from __future__ import annotations

import statistics
import textwrap
import time

import pytest

from quaddance.children import HelperError, HelperProcess


def _wait_dead(helper: HelperProcess, timeout_s: float = 20.0) -> bool:
    end = time.monotonic() + timeout_s
    while helper._proc.is_alive() and time.monotonic() < end:
        time.sleep(0.05)
    return not helper._proc.is_alive()


def test_calls_run_in_order_and_failures_are_reported():
    helper = HelperProcess()
    try:
        helper.submit(statistics.mean, data=[1, 2, 6])
        helper.submit(textwrap.dedent, text="  a")
        assert helper.result() == 3
        assert helper.result() == "a"
        with pytest.raises(HelperError, match="StatisticsError"):
            helper.call(statistics.mean, data=[])
        assert helper.call(statistics.median, data=[5]) == 5  # it lives on after a failure
        with pytest.raises(HelperError, match="no call"):
            helper.result()
    finally:
        helper.close()
    assert _wait_dead(helper)
    assert helper._proc.exitcode == 0


def test_a_helper_ends_when_its_caller_goes_away():
    helper = HelperProcess()
    helper._conn.close()  # as when the caller's process ends without a word
    assert _wait_dead(helper)
    assert helper._proc.exitcode == 1


def test_calls_to_a_dead_helper_are_helper_errors():
    helper = HelperProcess()
    helper._proc.kill()
    helper._proc.join(timeout=20)
    with pytest.raises(HelperError, match="ended"):
        helper.call(statistics.mean, data=[1])
    helper.close()
    helper.close()  # twice is harmless


def _sleep(seconds: float) -> None:
    time.sleep(seconds)


def test_ready_says_whether_an_answer_is_waiting():
    helper = HelperProcess()
    try:
        assert not helper.ready()  # nothing asked
        helper.submit(_sleep, seconds=1.5)
        assert not helper.ready()  # asked, still sleeping there
        end = time.monotonic() + 30.0
        while not helper.ready() and time.monotonic() < end:
            time.sleep(0.05)
        assert helper.ready()
        assert helper.result() is None
        assert not helper.ready()  # read
    finally:
        helper.close()


def test_a_ctrl_c_while_helpers_start_is_handled_here_and_not_by_them():
    """A Ctrl-C to the whole process group while a helper starts inside
    `sigint_blocked_for_children`: this process handles it, at the block's end (not in the
    middle of a start), and the helper, which inherited the block, drops it and works on.
    The design before ignored SIGINT here meanwhile, and a Ctrl-C that Linux handed to
    another thread (numpy's BLAS threads, or this test's thread) was lost."""
    import os
    import signal
    import threading

    from quaddance.children import sigint_blocked_for_children

    received = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)  # does not block SIGINT: it may take it
    other.start()
    helper = None
    try:
        with sigint_blocked_for_children():
            os.kill(os.getpid(), signal.SIGINT)  # to the process: any thread may take it
            helper = HelperProcess()
            os.kill(helper._proc.pid, signal.SIGINT)  # it is still importing
            time.sleep(0.1)
            assert received == []  # held until the helpers have started
        assert received == [signal.SIGINT]
        assert helper.call(statistics.mean, data=[1, 3]) == 2  # the helper lives on
        os.kill(helper._proc.pid, signal.SIGINT)  # and ignores a later one too
        assert helper.call(statistics.mean, data=[2, 4]) == 3
    finally:
        stop.set()
        other.join()
        signal.signal(signal.SIGINT, previous)
        if helper is not None:
            helper.close()


def test_nested_blocks_hold_to_the_outer_end_and_other_threads_block_only_themselves():
    import signal
    import threading

    from quaddance.children import sigint_blocked_for_children

    received = []

    def handler(signum, frame):
        received.append(signum)

    previous = signal.signal(signal.SIGINT, handler)
    try:
        with sigint_blocked_for_children():
            with sigint_blocked_for_children():
                pass
            # Still blocked after the inner block: a Ctrl-C waits for the outer one's end.
            signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)
            assert signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, [])
            assert received == []
        assert received == [signal.SIGINT]
        assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, [])

        masks = []

        def start_helpers_here():
            with sigint_blocked_for_children():
                masks.append(signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, []))
            masks.append(signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, []))

        worker = threading.Thread(target=start_helpers_here)
        worker.start()
        worker.join()
        assert masks == [True, False]  # helpers started there inherit the block
        assert signal.getsignal(signal.SIGINT) is handler  # this process's handler stays
    finally:
        signal.signal(signal.SIGINT, previous)
