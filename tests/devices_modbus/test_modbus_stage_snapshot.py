"""The emulated drive's status and position in one read come from a consistent moment: a
"not moving" status is never paired with a position from before the move ended (the virtual
clock runs on between the two registers' refreshes)."""

from modbus_testkit import STAGE_MAP  # noqa: I001 - the test folder's own fixtures
from ticking_clock import TickingClock

from sim.devices.modbus_stage import ModbusStageEmulator


def test_a_not_moving_status_comes_with_the_final_position():
    for step in (0.001 * k for k in range(1, 40)):  # where the move ends between two reads
        check_moves(ModbusStageEmulator(TickingClock(step), STAGE_MAP, (-95.0, 95.0), 20.0,
                                        80.0))


def check_moves(stage: ModbusStageEmulator) -> None:
    """Move to a few targets, polling status and position together until not moving."""
    layout = stage.layout
    status_address = layout.fields["status"].address
    position_address = layout.fields["actual_position"].address
    first = min(status_address, position_address)
    count = max(status_address, position_address) + 2 - first
    for target in (10.0, -3.7, 42.25, 42.0):
        stage.write(layout.fields["target_position"].address,
                    layout.to_words("target_position", target))
        stage.write(layout.fields["command"].address, [layout.commands["start"]])
        for _ in range(10_000):
            words = stage.read("holding", first, count)
            status = words[status_address - first]
            at = position_address - first
            position = layout.from_words("actual_position", words[at:at + 2])
            if not status >> layout.bits["moving"] & 1:
                break
        assert abs(position - target) < 1e-6, (target, position)
