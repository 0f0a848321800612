"""The sink image end to end: three sensor-node images and the sink image on one virtual CAN
bus, the sink's ESP8266 model dialling a real mocapd over loopback TCP (docs/firmware.md,
"Firmware in the loop").

One emulated network serves the whole module (booting it is most of the cost); the tests run
in order, each continuing from where the previous left it: streaming, the link dropped
(`CLOSED`), the module answering `ERROR`, mocapd restarted. Every wait is
for an event with a deadline in virtual time (deterministic) and mocapd's /metrics read after
each step, so a loaded host only makes the test slower.
"""

import os

import pytest

from mocapd_process import Mocapd
from sink_bus_rig import SinkBusRig
from virtual_clock import TICK_HZ

NODES = 3
RATE_HZ = 100
STEP_S = 0.02  # virtual time between looks at mocapd's metrics
PREFIX = "mocapd_ingest_tcp_"


def _elfs():
    paths = [os.environ["FIRMWARE_F103_ELF"]] + os.environ["FIRMWARE_F103_NODE_ELFS"].split(";")
    return os.environ["FIRMWARE_F407_ELF"], paths[:NODES]


class Network:
    def __init__(self, rig, daemon):
        self.rig, self.daemon = rig, daemon

    def m(self, name):
        return self.daemon.metric(PREFIX + name)

    def run_until(self, what, condition, limit_s):
        """Runs the network until `condition()` holds, looking every STEP_S of virtual time;
        fails after `limit_s` of virtual time."""
        end = self.rig.clock.ticks + int(limit_s * TICK_HZ)
        while not condition():
            assert self.rig.fault() is None, self.rig.fault()
            if self.rig.clock.ticks >= end:
                pytest.fail(f"{what}: not within {limit_s} s of virtual time; metrics "
                            f"{ {k: v for k, v in self.daemon.metrics().items() if k.startswith(PREFIX) and v} }")
            self.rig.run_for(STEP_S)
        return self.rig.clock.ticks / TICK_HZ

    def samples_flow(self, count, limit_s):
        """Waits for `count` more samples, every node's, at mocapd."""
        before = self.m("samples_total")
        return self.run_until(f"{count} samples at mocapd", lambda: self.m("samples_total") >= before + count, limit_s)

    def violations(self):
        out = self.rig.sink.all_violations()
        for board in self.rig.boards:
            out += board.all_violations()
        return out


@pytest.fixture(scope="module")
def net(tmp_path_factory):
    sink_elf, node_elfs = _elfs()
    daemon = Mocapd(tmp_path_factory.mktemp("mocapd")).start()
    rig = SinkBusRig(sink_elf, node_elfs, daemon.sink_address)
    rig.sink.esp.join_us = 100_000  # an access point that answers at once: less to emulate
    try:
        yield Network(rig, daemon)
    finally:
        rc = daemon.stop()
        print(f"\nvirtual {rig.clock.ticks / TICK_HZ:.2f} s; sink {rig.sink.cpu.clock.cycles} cycles; "
              f"ESP8266: {rig.sink.esp.connects} connections, {rig.sink.esp.sent_bytes} bytes sent; commands "
              f"{[(round(t / TICK_HZ, 3), line) for t, line in rig.sink.esp.log if not line.startswith('AT+CIPSEND')]}")
        assert rc in (0, None), "mocapd must drain and exit 0 on SIGTERM:\n" + daemon.log()


def test_the_sink_boots_joins_and_streams_every_node_into_mocapd(net):
    up = net.run_until("the sink connects", lambda: net.m("connections_accepted_total") >= 1, 5.0)
    assert net.rig.sink.rcc.hclk_hz() == 168_000_000
    t = net.samples_flow(NODES * 50, 3.0)
    syncs = net.m("sync_frames_total")
    samples = net.m("samples_total")
    print(f"\nsink connected at {up:.3f} s; at {t:.3f} s mocapd has {samples:.0f} samples in {syncs:.0f} SYNCs")
    assert net.rig.sink.led_on(), "PD12 is on while the uplink is up"
    assert samples >= NODES * 50
    assert samples <= NODES * syncs, "no sample without its SYNC"
    for bad in ("malformed_packets_total", "malformed_frames_total", "crc_failures_total", "garbage_closes_total"):
        assert net.m(bad) == 0, bad
    assert net.daemon.metric("mocapd_route_samples_unknown_node_total") == 0
    assert net.rig.sink.usart1.framing_errors == 0 and net.rig.sink.usart1.overruns == 0
    assert net.rig.sink.esp.lost_bytes == 0
    assert net.violations() == []
    # The sink's SYNC is what the nodes sample on: every node answered the SYNCs of the stream.
    sync_ids = [f for f in net.rig.sink_frames() if f[1] == 0x000]
    assert len(sync_ids) >= 50


def test_a_dropped_link_is_reconnected_and_the_stream_resumes(net):
    accepted = net.m("connections_accepted_total")
    net.rig.sink.esp.drop_link()
    net.run_until("the sink reconnects after CLOSED", lambda: net.m("connections_accepted_total") > accepted, 3.0)
    net.samples_flow(NODES * 20, 2.0)


def test_a_module_answering_error_is_retried_until_it_works(net):
    esp = net.rig.sink.esp
    accepted = net.m("connections_accepted_total")
    esp.errors = {"AT+CIPSTART"}
    esp.drop_link()
    tried = len([1 for _, line in esp.log if line.startswith("AT+CIPSTART")])
    net.run_until("two refused attempts", lambda: len([1 for _, line in esp.log if line.startswith("AT+CIPSTART")])
                  >= tried + 2, 5.0)
    assert net.m("connections_accepted_total") == accepted, "an ERROR is not a connection"
    esp.errors = set()
    net.run_until("the sink reconnects once the module works", lambda: net.m("connections_accepted_total") > accepted,
                  8.0)
    net.samples_flow(NODES * 20, 2.0)


def test_mocapd_restarting_is_survived(net):
    assert net.daemon.stop() == 0
    net.rig.run_for(0.3)  # the sink sees CLOSED and its attempts fail while no mocapd listens
    before = len([1 for _, line in net.rig.sink.esp.log if line.startswith("AT+CIPSTART")])
    net.daemon.start()
    net.run_until("the sink reconnects to the new mocapd", lambda: net.m("connections_accepted_total") >= 1, 10.0)
    net.samples_flow(NODES * 20, 2.0)
    assert len([1 for _, line in net.rig.sink.esp.log if line.startswith("AT+CIPSTART")]) > before
