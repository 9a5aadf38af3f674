"""Signals during training: SIGINT (Ctrl-C) and SIGTERM (what schedulers send before killing a job)
ask the training loop to stop at its next step boundary, where the state is consistent and a
resume exact; before the loop, or a second time, they stop at once. The handler only records the
request (or raises); what the loop then does (all ranks agree, ``last.pt`` is saved,
:class:`~posecons.errors.Interrupted` says how to resume) is the trainer's. Kept apart from it as
the one piece that runs whenever a signal arrives, and that forked DataLoader workers inherit."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading

from ..errors import Interrupted


class StopRequest:
    """SIGINT/SIGTERM during the training loop ask it to stop at the next step boundary, where the
    state is consistent and a resume exact; before the loop, or a second time, they stop at once."""

    def __init__(self) -> None:
        self.signum = 0
        self.in_loop = False
        self.pid = os.getpid()

    def _handle(self, signum: int, frame) -> None:
        if os.getpid() != self.pid:  # a forked DataLoader worker: it keeps loading, the trainer decides
            return
        name = signal.Signals(signum).name
        if self.in_loop and not self.signum:
            self.signum = signum
            print(f"\n{name}: stopping after this step (send it again to stop at once)", file=sys.stderr, flush=True)
            return
        raise Interrupted(f"stopped by {name}", signum)

    @contextlib.contextmanager
    def installed(self):
        if threading.current_thread() is not threading.main_thread():  # signals reach the main thread only
            yield self
            return
        previous = {
            s: signal.signal(s, self._handle)
            for s in (signal.SIGINT, signal.SIGTERM)
            if signal.getsignal(s) is not signal.SIG_IGN
        }  # e.g. SIGINT under nohup stays ignored
        try:
            yield self
        finally:
            for s, handler in previous.items():
                signal.signal(s, handler)
