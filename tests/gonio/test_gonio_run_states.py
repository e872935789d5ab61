"""The run states' table (gonio.run_control.TRANSITIONS): every state has its row, the moves
the engine and the requests make follow it, and a move it lacks is refused."""

import pytest

from gonio.events import State
from gonio.run_control import CHANNEL, TRANSITIONS, PauseControl


def test_every_state_has_a_row_and_every_row_names_states():
    assert set(TRANSITIONS) == set(State)
    assert all(targets <= set(State) for targets in TRANSITIONS.values())


def test_a_channel_pause_resume_and_abort_walk_the_table():
    control = PauseControl()
    control.enter(State.RUNNING)
    assert control.request_pause(CHANNEL) is State.PAUSING
    assert control.request_resume() is State.RUNNING
    assert control.request_abort("stop here") is State.STOPPING
    control.enter(State.ABORTED)
    assert control.state is State.ABORTED


def test_once_stopping_the_engines_own_steps_leave_the_state():
    control = PauseControl()
    control.request_abort("before the first reading")
    control.enter(State.RUNNING)  # the engine has not seen the abort yet
    assert control.state is State.STOPPING


def test_a_move_the_table_lacks_is_refused():
    control = PauseControl()
    with pytest.raises(RuntimeError, match="starting cannot change to suspended"):
        control.enter(State.SUSPENDED)
