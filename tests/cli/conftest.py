"""Command-line tests that send SIGINT to a child process need the child to
start with SIGINT's default disposition. A shell starts a background job
(`pytest ... &`) with SIGINT ignored, and that inherited SIG_IGN reaches every
child: clvis keeps an ignored SIGINT ignored, as a background job should, so the
signal tests would see the command run to the end. Give the children the
default (a handler installed here is reset to SIG_DFL at their exec)."""

import signal

import pytest


@pytest.fixture(autouse=True)
def _children_get_default_sigint():
    before = signal.getsignal(signal.SIGINT)
    if before == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        if before == signal.SIG_IGN:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
