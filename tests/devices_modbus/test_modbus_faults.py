"""Each injected fault type against the Modbus drivers, over TCP and RTU on a pty: the driver
either recovers (reads are retried) or fails with a named, bounded error; a motion command
is never sent twice."""

import time

import pytest
from modbus_testkit import STAGE_MAP, endpoint_args  # noqa: I001
from waiting import wait_until

from drivers.base import DeviceTimeout, DriverError, ProtocolError
from drivers.modbus_stage import ModbusStage
from sim.devices.faults import FaultInjector, FaultSpec
from sim.devices.modbus_server import ModbusEmulatorServer

TRANSPORTS = ["tcp", "rtu"]


class StallWriteReplies(FaultInjector):
    """Swallows every reply to a write (function 16): the write acts, its answer is lost."""

    def reply(self, data, keep_tail=0, crc_bytes=0):
        function = data[1] if crc_bytes else data[7]
        return None if function == 16 else super().reply(data, keep_tail, crc_bytes)


def count_commands(emulator):
    """Record the commands a stage emulator acts on (a spy on the device, not the link)."""
    seen = []
    act = emulator.act

    def spy(fields):
        if "command" in {f.name for f in fields}:
            seen.append(emulator.registers.get("command"))
        act(fields)

    emulator.act = spy
    return seen


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_latency_below_the_timeout_only_slows_replies(rig, transport):
    r = rig(transport, stage_faults={"latency_s": 0.25}, reply_s=1.0)
    t0 = time.monotonic()
    assert r.stage.position() == 0.0
    assert time.monotonic() - t0 >= 0.25
    assert r.server.late_replies == 1
    r.detector.read()  # another unit on the endpoint is not delayed
    assert r.server.late_replies == 1


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_latency_past_the_timeout_is_a_bounded_named_timeout(rig, transport):
    r = rig(transport, stage_faults={"latency_s": 0.3}, reply_s=0.05, read_retries=1)
    with pytest.raises(DeviceTimeout, match="sample: timeout after 0.05 s waiting for holding"):
        r.stage.position()
    # the late replies arrive; they must not answer the next query
    wait_until(lambda: r.server.late_replies == 2 and not r.server.late_pending,
               what="the late replies")
    assert r.stage_emu.faults.replies == 2  # two tries, bounded
    assert r.detector.read().range_w == 1e-4


@pytest.mark.parametrize("transport, kind", [
    ("tcp", "drop_prob"), ("tcp", "corrupt_prob"), ("tcp", "stall_prob"),
    ("rtu", "drop_prob"), ("rtu", "corrupt_prob"), ("rtu", "stall_prob"),
    ("rtu", "bad_crc_prob")])
def test_reads_recover_from_garbled_or_lost_replies(rig, transport, kind):
    # on RTU a retry is an echo and a read, each lost with p = 0.3; on a loaded machine a
    # reply may also miss the 0.05 s timeout: ten retries keep all 25 reads from running out
    r = rig(transport, stage_faults={kind: 0.3, "seed": 11}, reply_s=0.05, read_retries=10)
    # put the axis at 12.5 on the emulator's side (instant clock): a write is never retried, so
    # a move through the faulty link could fail when its one reply is lost or late
    r.stage_emu.axis.move_to(12.5)
    values = [r.stage.position() for _ in range(25)]
    assert values == [12.5] * 25  # never a wrong value, whatever the fault
    counts = r.stage_emu.faults.counts
    assert counts[kind.removesuffix("_prob")] > 0


def test_bad_crc_means_nothing_on_tcp(rig):
    r = rig("tcp", stage_faults={"bad_crc_prob": 1.0}, read_retries=0)
    assert [r.stage.position() for _ in range(5)] == [0.0] * 5
    assert r.stage_emu.faults.counts["bad_crc"] == 0


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_every_reply_bad_crc_or_stalled_gives_a_timeout(rig, transport):
    kind = "bad_crc_prob" if transport == "rtu" else "stall_prob"
    # reply_s 0.5: a reply that missed its wait on a loaded machine would be late, not garbled
    # or lost, and its attempt would follow another path (counted differently below)
    r = rig(transport, stage_faults={kind: 1.0}, reply_s=0.5, read_retries=2)
    with pytest.raises(DeviceTimeout, match="sample: timeout after 0.5 s"):
        r.stage.position()
    # the first try and two retries, no more (on RTU each retry follows the echo that brings
    # the line back in step after a timeout: drivers.modbus_rtu_sync)
    expected = 5 if transport == "rtu" else 3
    faults = r.stage_emu.faults
    # the server may still be busy with the last request
    wait_until(lambda: faults.replies >= expected, what=f"{expected} replies")
    r.stage_emu.faults = FaultInjector(FaultSpec())
    assert r.stage.position() == 0.0  # answered after every request sent before it
    assert faults.replies == expected


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_lost_reply_to_a_move_is_resolved_by_reading_state_not_resending(rig, transport):
    r = rig(transport, reply_s=0.05)
    seen = count_commands(r.stage_emu)
    r.stage_emu.faults = StallWriteReplies(FaultSpec())
    r.stage.move_to(42.0)  # target write and start: both replies lost, both acted on
    assert r.stage.wait(1.0) == 42.0
    assert seen == [r.stage.map.commands["start"]]  # sent exactly once


def test_lost_reply_to_home_is_resolved_by_the_homed_bit(rig):
    r = rig("rtu", reply_s=0.05)
    r.stage.move_to(20.0)
    seen = count_commands(r.stage_emu)
    r.stage_emu.faults = StallWriteReplies(FaultSpec())
    r.stage.home()
    assert r.stage.wait(1.0) == 0.0 and r.stage.homed()
    assert seen == [r.stage.map.commands["home"]]


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_lost_reply_to_stop_is_reported_not_resent(rig, transport):
    r = rig(transport, reply_s=0.05, time_scale=1.0)
    r.stage_emu.axis.move_to(90.0)  # moving (started on the emulator's side: only stop is tested)
    seen = count_commands(r.stage_emu)
    r.stage_emu.faults = StallWriteReplies(FaultSpec())
    with pytest.raises(DeviceTimeout, match="waiting for reply to a write"):
        r.stage.stop()
    assert seen == [r.stage.map.commands["stop"]]


def test_tcp_disconnect_is_a_named_error_and_the_next_query_reconnects(rig):
    r = rig("tcp", stage_faults={"disconnect_after": 2})
    assert r.stage.position() == 0.0
    assert r.stage.position() == 0.0  # the second reply arrives, then the drive hangs up
    with pytest.raises(DriverError, match=r"sample: connection to 127.0.0.1:\d+ failed or lost"):
        r.stage.position()
    assert r.stage.position() == 0.0  # a new connection (which it hangs up again)


def test_rtu_disconnect_cuts_the_line_for_good(rig):
    r = rig("rtu", server_faults={"disconnect_after": 1}, reply_s=0.05)
    assert r.stage.position() == 0.0
    for _ in range(2):
        with pytest.raises(DriverError, match="sample: connection to /dev/pts/"):
            r.stage.position()
    assert r.server.disconnected


def test_server_wide_faults_hit_units_without_their_own(rig):
    r = rig("rtu", server_faults={"corrupt_prob": 1.0}, stage_faults={"latency_s": 0.0},
            reply_s=0.05, read_retries=0)
    assert r.stage.position() == 0.0  # the stage has its own (harmless) injector
    with pytest.raises((DeviceTimeout, DriverError)):
        r.detector.read()
    assert r.server.faults.counts["corrupt"] == 1


def test_fault_sequence_is_reproducible_from_the_seed(rig):
    runs = []
    for _ in range(2):
        # reply_s long enough that no good reply misses it on a loaded machine (an extra
        # request would draw faults for an extra reply)
        r = rig("tcp", stage_faults={"drop_prob": 0.5, "seed": 5}, reply_s=0.15,
                read_retries=8)
        for _ in range(10):
            r.stage.position()
        runs.append((r.stage_emu.faults.replies, dict(r.stage_emu.faults.counts)))
    assert runs[0] == runs[1]


class WrongCountUnit:
    """A broken device: answers every read with one register too many."""

    faults = None

    def __init__(self):
        self.reads = 0

    def read(self, table, address, count):
        self.reads += 1
        return [0] * (count + 1)

    def write(self, address, values):
        pass


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_reply_with_the_wrong_register_count_is_a_protocol_error(transport, tmp_path):
    unit = WrongCountUnit()
    server = ModbusEmulatorServer(transport, {1: unit})
    server.start()
    transport, where, kw = endpoint_args(server)
    try:
        with ModbusStage(transport, where, 1, STAGE_MAP, name="odd", read_retries=1, **kw) as st:
            with pytest.raises(ProtocolError, match="odd: holding registers 8..9 of unit 1: 3 "
                                                    "registers in the reply, expected 2"):
                st.position()
        assert unit.reads == 2  # a query: tried once more, then reported
    finally:
        server.stop()
