"""hybridev.core.cleanup: clean-up on exit and on SIGINT/SIGTERM."""

import os
import signal
import time

import pytest

from hybridev.core.cleanup import guard


@pytest.fixture(autouse=True)
def default_sigint():
    """Python's own SIGINT handler for the test (another test or library may have changed it)."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


def _interrupt_and_swallow():
    """Deliver SIGINT and lose its KeyboardInterrupt, as a finaliser (__del__) would."""
    try:
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.5)  # the handler runs at the next bytecode
    except KeyboardInterrupt:
        return True
    return False


def test_action_runs_on_normal_exit_and_on_error():
    done = []
    with guard(lambda: done.append("ok")):
        pass
    with pytest.raises(ValueError), guard(lambda: done.append("error")):
        raise ValueError("x")
    assert done == ["ok", "error"]


def test_sigint_runs_the_action_and_a_lost_interrupt_is_raised_again():
    done = []
    with pytest.raises(KeyboardInterrupt), guard(lambda: done.append(1)):
        assert _interrupt_and_swallow()
    assert done  # the clean-up ran
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    with guard(lambda: None):  # nothing left over: the next guard ends normally
        pass


def test_an_interrupt_that_propagates_is_not_raised_twice():
    with pytest.raises(KeyboardInterrupt), guard(lambda: None):
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.5)
    with guard(lambda: None):
        pass
