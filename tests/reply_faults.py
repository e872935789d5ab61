"""Fault injectors that spoil the next few replies of an emulator in one set way (the device
acts on the lines; its answers are lost or garbled), and a spy on the lines it receives, for
tests of what a driver does then."""

from collections.abc import Callable

from sim.devices.faults import FaultInjector, FaultSpec


class SpoilNext(FaultInjector):
    """Sends spoil(reply) in place of each of the next `n` replies (None: nothing sent)."""

    def __init__(self, n: int, spoil: Callable[[bytes], bytes | None]):
        super().__init__(FaultSpec())
        self.left, self.spoil = n, spoil

    def reply(self, data, keep_tail=0, crc_bytes=0):
        if self.left:
            self.left -= 1
            return self.spoil(data)
        return super().reply(data, keep_tail, crc_bytes)


class StallNext(SpoilNext):
    """Swallows the next `n` replies."""

    def __init__(self, n: int):
        super().__init__(n, lambda data: None)


class GarbleNext(SpoilNext):
    """Sets the high bit of the first byte of the next `n` replies."""

    def __init__(self, n: int):
        super().__init__(n, lambda data: bytes([data[0] | 0x80]) + data[1:])


def spy_lines(emu) -> list[str]:
    """The lines a line emulator receives (each as text, its terminator stripped), recorded on
    the emulator's side of the pty."""
    seen = []
    handle = emu.server.handler

    def spy(line):
        seen.append(line.decode())
        return handle(line)

    emu.server.handler = spy
    return seen


def read_through_faults(emu, read: Callable[[], object], count: int, seed: int) -> list:
    """`count` values of read() while the emulator's replies meet seeded corrupted, dropped
    and stalled bytes (each kind of fault met at least once: checked)."""
    emu.server.faults = FaultInjector(FaultSpec(corrupt_prob=0.15, drop_prob=0.15,
                                                stall_prob=0.05, seed=seed))
    values = [read() for _ in range(count)]
    met = emu.server.faults.counts
    assert met["corrupt"] > 0 and met["drop"] > 0 and met["stall"] > 0, met
    return values
