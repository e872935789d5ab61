"""Who may pause, resume and abort a run, and the engine's state they act on.

The terminal (SIGINT, SIGTERM, SIGHUP and the prompts on stderr/stdin) and the control channel
(gonio.control, another thread) ask; the engine's thread acts, before the next reading. The
first Ctrl-C asks for a pause, answered at the terminal prompt; a Ctrl-C while a pause is asked
for or in effect aborts at once; SIGTERM and SIGHUP raise Terminated. A pause asked for on the
channel waits on the channel (resume or abort there, or Ctrl-C: abort), never on the terminal.
An abort from the channel interrupts the engine's thread as a second Ctrl-C does.
While the run directory is made, signals wait (`deferring`) and act once it exists; once the
run has ended they are ignored (`hold`) until its devices are closed (`held_until_closed`), so
no later signal changes how the run ended.

Every change of state goes through `PauseControl._move`, which checks it against
`TRANSITIONS`, the whole table.
"""

from __future__ import annotations

import _thread
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from gonio.errors import Terminated
from gonio.events import State

TERMINATING = (signal.SIGTERM, signal.SIGHUP)
HANDLED = (signal.SIGINT, *TERMINATING)
TERMINAL, CHANNEL = "terminal", "channel"  # where a pause was asked for
POLL_S = 0.05  # how often a wait looks at the requests
_ENDS = (State.STOPPING, State.COMPLETED, State.ABORTED, State.FAILED)
# state -> the states it may move to. A final state may start again (running), or stop at
# once (a failed start): a queue runs its plans on one control.
TRANSITIONS: dict[State, frozenset[State]] = {
    State.STARTING: frozenset({State.RUNNING, State.PAUSING, State.STOPPING}),
    State.RUNNING: frozenset({State.RUNNING, State.PAUSING, State.PAUSED, State.SUSPENDED,
                              State.STOPPING}),
    State.PAUSING: frozenset({State.RUNNING, State.PAUSED, State.SUSPENDED, State.STOPPING}),
    State.PAUSED: frozenset({State.RUNNING, State.PAUSING, State.STOPPING}),
    State.SUSPENDED: frozenset({State.RUNNING, State.PAUSING, State.STOPPING}),
    State.STOPPING: frozenset(_ENDS),
    **{end: frozenset({State.RUNNING, State.PAUSING, State.STOPPING}) for end in _ENDS[1:]},
}


class Aborted(Exception):
    """The user aborted the run."""


def _ask(question: str, yes: tuple[str, ...]) -> bool:
    """Ask on stderr, read stdin: True for an answer in `yes` (or empty), False for abort or
    end of input."""
    while True:
        sys.stderr.write(f"{question} ")
        sys.stderr.flush()
        line = sys.stdin.readline()
        if not line:
            return False
        answer = line.strip().lower()
        if answer in (*yes, ""):
            return True
        if answer in ("a", "abort"):
            return False


def ask_resume() -> bool:
    """Default pause prompt: True to resume, False to abort (end of input: abort)."""
    return _ask("paused: [r]esume or [a]bort?", ("r", "resume"))


def ask_continue(message: str) -> bool:
    """Default operator prompt: True to continue, False to abort (end of input: abort)."""
    return _ask(f"{message}: [c]ontinue or [a]bort?", ("c", "continue"))


def _notify(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


class PauseControl:
    """The run's state and the requests that change it; also the run's signal handling.
    Entered more than once (the runner before it makes the run directory, the engine), the
    outermost entry counts."""

    def __init__(self, prompt: Callable[[], bool] = ask_resume,
                 notify: Callable[[str], Any] = _notify,
                 confirm: Callable[[str], bool] = ask_continue):
        self.prompt, self.notify, self.confirm = prompt, notify, confirm
        self._lock = threading.RLock()  # a signal handler may run while the engine holds it
        self._state = State.STARTING
        self._pause_source: str | None = None  # asked for, or in effect
        self._pending: str | None = None  # asked for while starting or suspended
        self._answer: str | None = None  # the channel's answer to its pause: resume | abort
        self.abort_reason: str | None = None
        self._previous: dict[int, Any] = {}
        self._depth = 0
        self._engine_thread: int | None = None
        self._deferred: list[int] | None = None  # signals waiting for `deferring` to end
        self._holding = False  # signals ignored: the run has ended (`hold`)
        self._closing = 0  # depth of `held_until_closed`

    # -- the state --------------------------------------------------------------
    @property
    def state(self) -> State:
        """The engine's state now."""
        with self._lock:
            return self._state

    def _move(self, state: State) -> None:
        """Change to `state` (the lock held), as TRANSITIONS allows. Once stopping, the
        engine's own steps (running, suspended, paused) before it sees the abort leave the
        state as it is; any other move the table lacks is a RuntimeError."""
        if state in TRANSITIONS[self._state]:
            self._state = state
        elif self._state is not State.STOPPING:
            raise RuntimeError(f"run state {self._state.value} cannot change to {state.value}")

    def enter(self, state: State) -> None:
        """The engine's thread moves to `state` (a pause asked for while starting or
        suspended takes effect on entering RUNNING)."""
        with self._lock:
            if state is State.RUNNING and self._pending:
                self._move(State.PAUSING)
                self._pause_source, self._pending = self._pending, None
            else:
                self._move(state)

    # -- requests (any thread) --------------------------------------------------
    def request_pause(self, source: str = CHANNEL) -> State:
        """Ask for a pause before the next reading; returns the state it leaves."""
        with self._lock:
            if self._state is State.RUNNING:
                self._move(State.PAUSING)
                self._pause_source = source
            elif self._state in (State.STARTING, State.SUSPENDED) and not self._pending:
                self._pending = source
            return self._state

    def request_resume(self) -> State:
        """Resume a pause the channel asked for; ValueError (one line) if there is none."""
        with self._lock:
            if self._state is State.PAUSING and self._pause_source == CHANNEL:
                self._move(State.RUNNING)
                self._pause_source = None
            elif self._state is State.PAUSED and self._pause_source == CHANNEL:
                self._answer = "resume"
                self._move(State.RUNNING)
            elif self._state is State.PAUSED:
                raise ValueError("paused at the terminal prompt: answer it there")
            else:
                raise ValueError(f"not paused ({self._state.value})")
            return self._state

    def request_abort(self, reason: str) -> State:
        """End the run (axes stopped) as a Ctrl-C abort does, with `reason`."""
        with self._lock:
            if self._state.final or self.abort_reason is not None:
                return self._state
            self.abort_reason, self._answer = reason, "abort"
            interrupt = self._state is not State.PAUSED or self._pause_source != CHANNEL
            self._move(State.STOPPING)
        if interrupt and self._previous and self._engine_thread == threading.main_thread().ident:
            _thread.interrupt_main(signal.SIGINT)  # as a second Ctrl-C: at once, mid-move too
        return State.STOPPING

    # -- signals ----------------------------------------------------------------
    def _on_signal(self, signum: int, frame: Any) -> None:
        if self._deferred is not None:
            self._deferred.append(signum)
        elif signum == signal.SIGINT:
            self._on_sigint()
        else:
            self._on_terminate(signum)

    def _on_sigint(self) -> None:
        with self._lock:
            aborting = (self.abort_reason is not None or self._pending is not None
                        or self._state in (State.PAUSING, State.PAUSED))
        if aborting:
            self.hold()
            raise KeyboardInterrupt
        self.request_pause(TERMINAL)
        self.notify("pausing after this point (Ctrl-C again to abort)")

    def _on_terminate(self, signum: int) -> None:
        self.hold()
        raise Terminated(signum)

    @contextmanager
    def deferring(self) -> Iterator[None]:
        """Signals that arrive inside the block act once it ends without an error: what the
        block makes (the run directory and its writer) is whole before a signal ends the run."""
        self._deferred = []
        try:
            yield
        finally:
            deferred, self._deferred = self._deferred, None
        for signum in deferred:
            self._on_signal(signum, None)

    def hold(self) -> None:
        """Ignore these signals from now on (until the outermost exit, or the end of
        `held_until_closed`): the run is ending, and stopping the axes and recording why must
        not be interrupted."""
        if self._previous:
            self._holding = True
            for sig in HANDLED:
                signal.signal(sig, signal.SIG_IGN)

    @contextmanager
    def held_until_closed(self) -> Iterator[None]:
        """A hold that starts inside the block lasts to its end (past the outermost exit): the
        runner wraps the run's devices in it, so a signal after the run has ended cannot
        interrupt their closing. Then the handlers in place before the run come back (this
        control's own while an outer entry, a queue's, still holds it)."""
        self._closing += 1
        try:
            yield
        finally:
            self._closing -= 1
            if not self._closing and self._holding:
                self._holding = False
                if self._depth:
                    self._install()
                else:
                    self._restore()

    def _install(self) -> None:
        for sig in HANDLED:  # one ignored on entry (nohup, a background job) stays so
            if self._previous[sig] is not signal.SIG_IGN:
                signal.signal(sig, self._on_signal)

    def _restore(self) -> None:
        for sig, previous in self._previous.items():
            signal.signal(sig, previous)
        self._previous = {}

    def __enter__(self) -> PauseControl:
        self._depth += 1
        if self._depth == 1 and not self._previous:
            self._engine_thread = threading.get_ident()
            if self._engine_thread == threading.main_thread().ident:
                self._previous = {sig: signal.getsignal(sig) or signal.SIG_DFL for sig in HANDLED}
                self._install()
        return self

    def __exit__(self, *exc: object) -> None:
        self._depth -= 1
        if self._depth == 0 and not (self._closing and self._holding):
            self._holding = False
            self._restore()

    # -- the engine's side ------------------------------------------------------
    def check_abort(self) -> None:
        """Raise Aborted if the channel asked for an abort."""
        if self.abort_reason is not None:
            raise Aborted(self.abort_reason)

    def checkpoint(self, on_pause: Callable[[], None], on_resume: Callable[[], None]) -> None:
        """Between points: if a pause was asked for, pause (on_pause), wait for the answer
        where it was asked, then go on (on_resume) or raise Aborted."""
        self.check_abort()
        with self._lock:
            if self._state is not State.PAUSING:
                return
            self._move(State.PAUSED)
            source = self._pause_source
        on_pause()
        resume = self._answer_on_channel() if source == CHANNEL else self._answer_on_terminal()
        if not resume:
            raise Aborted(self.abort_reason or "aborted by the user")
        self.enter(State.RUNNING)
        with self._lock:
            self._pause_source = None
        on_resume()

    def pause_reason(self) -> str:
        """Who asked for the pause in effect, as meta.json records it."""
        return ("paused from the control channel" if self._pause_source == CHANNEL
                else "paused by the user")

    def _answer_on_terminal(self) -> bool:
        try:
            return self.prompt()
        except (KeyboardInterrupt, EOFError):
            return False

    def _answer_on_channel(self) -> bool:
        """Wait for the channel's resume or abort (a Ctrl-C meanwhile aborts)."""
        try:
            while True:
                with self._lock:
                    answer, self._answer = self._answer, None
                if answer is not None:
                    return answer == "resume"
                threading.Event().wait(POLL_S)
        except KeyboardInterrupt:
            return False

    def wait(self, seconds: float) -> None:
        """Sleep `seconds` (a suspension's wait) unless the channel aborts (Aborted)."""
        done = threading.Event()
        remaining = seconds
        while remaining > 0:
            self.check_abort()
            done.wait(min(POLL_S, remaining))
            remaining -= POLL_S
        self.check_abort()

    def operator_step(self, message: str, on_pause: Callable[[str], None],
                      on_resume: Callable[[], None]) -> None:
        """Wait for the operator to do what `message` asks by hand; raise Aborted to abort."""
        self.enter(State.PAUSED)
        on_pause(message)
        try:
            go_on = self.confirm(message)
        except (KeyboardInterrupt, EOFError):
            go_on = False
        if not go_on:
            raise Aborted(self.abort_reason or f"aborted by the user at: {message}")
        self.enter(State.RUNNING)
        on_resume()
