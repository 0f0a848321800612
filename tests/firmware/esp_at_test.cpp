// The ESP8266 AT uplink against a scripted modem that answers like the AT firmware (echo
// until ATE0, "ready" after reset, '>' prompt for CIPSEND, unsolicited CLOSED), and with the
// sink core on top of it.
#include <gtest/gtest.h>

#include <algorithm>
#include <deque>
#include <memory>
#include <string>
#include <vector>

#include "mocap_wire/mw_keepalive.h"
#include "mocap_wire/mw_packet.h"
#include "sink_node/esp_at.h"
#include "sink_node/sink_node.h"

namespace mocap::test {
namespace {

struct fake_modem {
    // Knobs
    std::string ssid = "my,net";
    std::string password = "pa\"ss";
    bool server_up = true;
    bool silent = false;
    // State
    uint64_t now_us = 1'000'000;
    uint32_t modem_baud = 115200;
    uint32_t port_baud = 115200;
    bool echo = true;
    bool connected = false;
    std::size_t data_left = 0;
    std::string line;
    std::deque<std::pair<uint8_t, uint32_t>> to_client;  // byte, baud rate it is sent at
    std::vector<std::string> commands;
    std::vector<std::vector<uint8_t>> payloads;
    std::size_t port_capacity = 64;  // bytes the UART takes per write call

    void say(const std::string& s) {
        for (char c : s) {
            to_client.emplace_back(static_cast<uint8_t>(c), modem_baud);
        }
    }

    // The host sends bytes: the module announces them as "+IPD,<n>:" and passes them raw.
    void host_sends(const std::vector<uint8_t>& bytes) {
        say("\r\n+IPD," + std::to_string(bytes.size()) + ":");
        say(std::string(bytes.begin(), bytes.end()));
    }

    void peer_close() {
        connected = false;
        say("CLOSED\r\n");
    }

    void on_command(const std::string& cmd) {
        commands.push_back(cmd);
        if (silent) {
            return;
        }
        if (echo) {
            say(cmd + "\r\n");
        }
        if (cmd == "AT+RST") {
            say("\r\nOK\r\n");
            say(std::string("\x02\xfe rl\x80 boot garbage\r\n"));
            modem_baud = 115200;
            echo = true;
            connected = false;
            say("\r\nready\r\n");
        } else if (cmd == "ATE0") {
            echo = false;
            say("\r\nOK\r\n");
        } else if (cmd.rfind("AT+UART_CUR=", 0) == 0) {
            say("\r\nOK\r\n");
            modem_baud = static_cast<uint32_t>(std::stoul(cmd.substr(12)));
        } else if (cmd == "AT+CWMODE=1" || cmd == "AT+CIPMUX=0") {
            say("\r\nOK\r\n");
        } else if (cmd.rfind("AT+CWJAP=", 0) == 0) {
            const std::string expected = "AT+CWJAP=\"my\\,net\",\"pa\\\"ss\"";
            if (cmd == expected && ssid == "my,net" && password == "pa\"ss") {
                say("WIFI DISCONNECT\r\nWIFI CONNECTED\r\nWIFI GOT IP\r\n\r\nOK\r\n");
            } else {
                say("+CWJAP:1\r\n\r\nFAIL\r\n");
            }
        } else if (cmd.rfind("AT+CIPSTART=", 0) == 0) {
            if (server_up) {
                connected = true;
                say("CONNECT\r\n\r\nOK\r\n");
            } else {
                say("ERROR\r\nCLOSED\r\n");
            }
        } else if (cmd.rfind("AT+CIPSEND=", 0) == 0) {
            if (!connected) {
                say("link is not valid\r\n\r\nERROR\r\n");
                return;
            }
            data_left = std::stoul(cmd.substr(11));
            payloads.emplace_back();
            say("\r\nOK\r\n> ");
        } else if (cmd == "AT+CIPCLOSE") {
            connected = false;
            say("CLOSED\r\n\r\nOK\r\n");
        } else {
            say("\r\nERROR\r\n");
        }
    }

    void from_client(uint8_t c) {
        if (port_baud != modem_baud) {
            return;  // framing errors: the modem sees nothing sensible
        }
        if (data_left > 0) {
            payloads.back().push_back(c);
            if (--data_left == 0) {
                say("\r\nRecv " + std::to_string(payloads.back().size()) + " bytes\r\n\r\nSEND OK\r\n");
            }
            return;
        }
        if (c == '\n') {
            if (!line.empty() && line.back() == '\r') {
                line.pop_back();
            }
            on_command(line);
            line.clear();
        } else {
            line.push_back(static_cast<char>(c));
        }
    }

    esp_at_serial serial() {
        esp_at_serial s{};
        s.user = this;
        s.write = [](void* u, const uint8_t* d, size_t n) {
            auto* m = static_cast<fake_modem*>(u);
            const size_t take = n < m->port_capacity ? n : m->port_capacity;
            for (size_t i = 0; i < take; ++i) {
                m->from_client(d[i]);
            }
            return take;
        };
        s.read = [](void* u, uint8_t* d, size_t cap) {
            auto* m = static_cast<fake_modem*>(u);
            size_t n = 0;
            while (n < cap && !m->to_client.empty()) {
                const auto [byte, baud] = m->to_client.front();
                m->to_client.pop_front();
                if (baud == m->port_baud) {  // sent at another rate: lost to framing errors
                    d[n++] = byte;
                }
            }
            return n;
        };
        s.set_baud = [](void* u, uint32_t baud) { static_cast<fake_modem*>(u)->port_baud = baud; };
        s.time_us = [](void* u) { return static_cast<fake_modem*>(u)->now_us; };
        return s;
    }
};

class EspAtTest : public ::testing::Test {
protected:
    fake_modem modem;
    std::unique_ptr<esp_at> at = std::make_unique<esp_at>();
    const char* const backups[1] = {"10.0.0.3"};
    const uint16_t backup_ports[1] = {7001};
    esp_at_config config{"my,net", "pa\"ss", "10.0.0.2", 7000, 921600, 1, backups, backup_ports};

    void SetUp() override {
        const esp_at_serial s = modem.serial();
        ASSERT_EQ(esp_at_init(at.get(), &s, &config), MW_OK);
    }

    sink_uplink_state settle(int polls = 50) {
        sink_uplink_state st = esp_at_state(at.get());
        for (int i = 0; i < polls; ++i) {
            modem.now_us += 1000;
            st = esp_at_state(at.get());
        }
        return st;
    }
};

TEST_F(EspAtTest, SetupScriptThenConnect) {
    ASSERT_EQ(esp_at_connect(at.get(), 0), 0);
    EXPECT_EQ(esp_at_state(at.get()) == SINK_UPLINK_UP ? 0 : 1, 1) << "takes more than one call";
    EXPECT_EQ(settle(), SINK_UPLINK_UP);
    const std::vector<std::string> expected{"AT+RST",
                                            "ATE0",
                                            "AT+UART_CUR=921600,8,1,0,0",
                                            "AT+CWMODE=1",
                                            "AT+CWJAP=\"my\\,net\",\"pa\\\"ss\"",
                                            "AT+CIPMUX=0",
                                            "AT+CIPSTART=\"TCP\",\"10.0.0.2\",7000"};
    EXPECT_EQ(modem.commands, expected);
    EXPECT_EQ(modem.port_baud, 921600u);
    EXPECT_EQ(at->wifi_ready, 1);
}

TEST_F(EspAtTest, SendsOnePacketAtATimeThroughThePrompt) {
    esp_at_connect(at.get(), 0);
    ASSERT_EQ(settle(), SINK_UPLINK_UP);
    std::vector<uint8_t> packet(300);
    for (std::size_t i = 0; i < packet.size(); ++i) {
        packet[i] = static_cast<uint8_t>(i * 7 + ('\n' == i ? 1 : 0));
    }
    ASSERT_EQ(esp_at_write(at.get(), packet.data(), packet.size()), 0);
    EXPECT_EQ(esp_at_write(at.get(), packet.data(), 10), 1) << "busy while the first is in flight";
    settle(5);
    ASSERT_EQ(modem.payloads.size(), 1u);
    EXPECT_EQ(modem.payloads[0], packet);
    EXPECT_EQ(modem.commands.back(), "AT+CIPSEND=300");
    EXPECT_EQ(at->counters.packets_sent, 1u);
    EXPECT_EQ(esp_at_write(at.get(), packet.data(), 10), 0) << "free again after SEND OK";
    settle(5);
    EXPECT_EQ(modem.payloads.size(), 2u);
    EXPECT_EQ(esp_at_write(at.get(), packet.data(), ESP_AT_MAX_PAYLOAD + 1), 1) << "too large for one CIPSEND";
}

TEST_F(EspAtTest, PeerCloseTakesLinkDownAndReconnectSkipsSetup) {
    esp_at_connect(at.get(), 0);
    ASSERT_EQ(settle(), SINK_UPLINK_UP);
    modem.peer_close();
    EXPECT_EQ(esp_at_state(at.get()), SINK_UPLINK_DOWN);
    EXPECT_EQ(at->counters.link_closed, 1u);
    const std::size_t before = modem.commands.size();
    esp_at_connect(at.get(), 0);
    EXPECT_EQ(settle(), SINK_UPLINK_UP);
    ASSERT_EQ(modem.commands.size(), before + 1);
    EXPECT_EQ(modem.commands.back(), "AT+CIPSTART=\"TCP\",\"10.0.0.2\",7000");
    EXPECT_EQ(at->counters.resets, 1u);
}

TEST_F(EspAtTest, ConnectsToTheHostOfTheListTheCoreAsksFor) {
    esp_at_connect(at.get(), 0);
    ASSERT_EQ(settle(), SINK_UPLINK_UP);
    modem.peer_close();
    EXPECT_EQ(esp_at_state(at.get()), SINK_UPLINK_DOWN);
    ASSERT_EQ(esp_at_connect(at.get(), 1), 0);
    EXPECT_EQ(settle(), SINK_UPLINK_UP);
    EXPECT_EQ(modem.commands.back(), "AT+CIPSTART=\"TCP\",\"10.0.0.3\",7001");
    modem.peer_close();
    EXPECT_EQ(esp_at_state(at.get()), SINK_UPLINK_DOWN);
    EXPECT_EQ(esp_at_connect(at.get(), 2), -1) << "no host 2 in a list of two";
}

TEST_F(EspAtTest, HostBytesArriveThroughIpdWhateverTheyContain) {
    esp_at_connect(at.get(), 0);
    ASSERT_EQ(settle(), SINK_UPLINK_UP);
    // Line ends, a "CLOSED" and a '>' inside the data are data, not module responses.
    const std::vector<uint8_t> odd{'C', 'L', 'O', 'S', 'E', 'D', '\r', '\n', '>', 0x00, 0xFF};
    modem.host_sends(odd);
    const mw_keepalive k{250, 3};
    std::vector<uint8_t> ka(MW_KEEPALIVE_SIZE);
    ASSERT_EQ(mw_keepalive_encode(&k, ka.data(), ka.size()), static_cast<int32_t>(MW_KEEPALIVE_SIZE));
    modem.host_sends(ka);
    EXPECT_EQ(settle(5), SINK_UPLINK_UP) << "the CLOSED inside the data must not close the link";
    uint8_t buf[64];
    const int n = esp_at_read(at.get(), buf, sizeof buf);
    ASSERT_EQ(n, static_cast<int>(odd.size() + ka.size()));
    EXPECT_TRUE(std::equal(odd.begin(), odd.end(), buf));
    EXPECT_TRUE(std::equal(ka.begin(), ka.end(), buf + odd.size()));
    EXPECT_EQ(esp_at_read(at.get(), buf, sizeof buf), 0);
    // A packet write still works after received data.
    const std::vector<uint8_t> packet(40, 0x11);
    ASSERT_EQ(esp_at_write(at.get(), packet.data(), packet.size()), 0);
    settle(5);
    ASSERT_EQ(modem.payloads.size(), 1u);
    // More than the buffer holds is dropped and counted, never overrun.
    modem.host_sends(std::vector<uint8_t>(ESP_AT_RX_MAX + 10, 0x22));
    settle(5);
    EXPECT_EQ(at->counters.rx_dropped, 10u);
    EXPECT_EQ(esp_at_read(at.get(), buf, sizeof buf), static_cast<int>(sizeof buf));
    modem.peer_close();
    EXPECT_EQ(esp_at_state(at.get()), SINK_UPLINK_DOWN);
    EXPECT_EQ(esp_at_read(at.get(), buf, sizeof buf), -1);
}

TEST_F(EspAtTest, ServerDownFailsConnectButKeepsWifi) {
    modem.server_up = false;
    esp_at_connect(at.get(), 0);
    EXPECT_EQ(settle(), SINK_UPLINK_DOWN);
    EXPECT_EQ(at->counters.errors, 1u);
    EXPECT_EQ(at->wifi_ready, 1);
}

TEST_F(EspAtTest, WrongPasswordFailsAndNextConnectResetsAgain) {
    modem.password = "other";
    esp_at_connect(at.get(), 0);
    EXPECT_EQ(settle(), SINK_UPLINK_DOWN);
    EXPECT_EQ(at->wifi_ready, 0);
    modem.password = "pa\"ss";
    esp_at_connect(at.get(), 0);
    EXPECT_EQ(settle(), SINK_UPLINK_UP);
    EXPECT_EQ(at->counters.resets, 2u);
}

TEST_F(EspAtTest, SilentModuleTimesOut) {
    modem.silent = true;
    esp_at_connect(at.get(), 0);
    EXPECT_EQ(settle(4000), SINK_UPLINK_CONNECTING) << "the reset may take 5 s";
    EXPECT_EQ(settle(1100), SINK_UPLINK_DOWN);
    EXPECT_EQ(at->counters.timeouts, 1u);
}

// Found by the sink image in the emulator (tests/firmware_loop, docs/firmware.md defect 4):
// a module that restarted by itself was dialled at the old rate forever.
TEST_F(EspAtTest, ModuleThatRestartedByItselfIsResetAfterItFallsSilent) {
    esp_at_connect(at.get(), 0);
    ASSERT_EQ(settle(), SINK_UPLINK_UP);
    // Brown-out or watchdog: back at 115200 baud, echo on, no connection; its "ready" is lost
    // to framing errors at the sink's 921600.
    modem.modem_baud = 115200;
    modem.echo = true;
    modem.connected = false;
    modem.say("\r\nready\r\n");
    const std::vector<uint8_t> packet(40, 0x11);
    ASSERT_EQ(esp_at_write(at.get(), packet.data(), packet.size()), 0);
    EXPECT_EQ(settle(1100), SINK_UPLINK_DOWN) << "no SEND OK: the command times out";
    for (int attempt = 0; attempt < 3 && esp_at_state(at.get()) != SINK_UPLINK_UP; ++attempt) {
        esp_at_connect(at.get(), 0);
        settle(11000);
    }
    EXPECT_EQ(esp_at_state(at.get()), SINK_UPLINK_UP);
    EXPECT_EQ(modem.port_baud, 921600u);
    EXPECT_EQ(at->counters.resets, 3u) << "power-on, the reset lost at 921600, the one at 115200";
}

TEST_F(EspAtTest, SinkCoreStreamsDecodablePacketsOverTheModem) {
    struct bus {
        fake_modem* modem;
    } clock{&modem};
    static bus* g_bus;
    g_bus = &clock;
    sink_node_hal hal{};
    esp_at_uplink(at.get(), &hal);
    hal.can_transmit = [](void*, const mw_can_frame*) { return 0; };
    hal.can_receive = [](void*, mw_can_frame*) { return 0; };
    hal.time_us = [](void*) { return g_bus->modem->now_us; };
    sink_node_config c{};
    sink_node_default_config(&c);
    c.status_period_s = 0;
    c.config_period_s = 0;
    auto sink = std::make_unique<sink_node>();
    ASSERT_EQ(sink_node_init(sink.get(), &hal, &c), MW_OK);
    for (int ms = 0; ms < 200; ++ms) {
        sink_node_poll(sink.get());
        modem.now_us += 1000;
    }
    EXPECT_EQ(sink->counters.connects, 1u);
    std::vector<uint8_t> stream;
    for (const auto& p : modem.payloads) {
        stream.insert(stream.end(), p.begin(), p.end());
    }
    auto decoder = std::make_unique<mw_stream_decoder>();
    mw_stream_decoder_init(decoder.get());
    auto packet = std::make_unique<mw_packet>();
    const uint8_t* p = stream.data();
    std::size_t n = stream.size();
    uint32_t packets = 0;
    for (;;) {
        std::size_t used = 0;
        const auto r = mw_stream_decoder_feed(decoder.get(), p, n, &used, packet.get());
        p += used;
        n -= used;
        if (r == MW_STREAM_NEED_MORE) {
            break;
        }
        ASSERT_EQ(r, MW_STREAM_PACKET);
        EXPECT_EQ(packet->header.sequence, packets);
        ++packets;
    }
    EXPECT_GE(packets, 15u) << "one per SYNC once connected";
    EXPECT_EQ(packets, sink->counters.packets_out);
}

TEST_F(EspAtTest, SinkCoreLeavesASilentHostForTheNextOverTheModem) {
    static fake_modem* g_modem;
    g_modem = &modem;
    sink_node_hal hal{};
    esp_at_uplink(at.get(), &hal);
    hal.can_transmit = [](void*, const mw_can_frame*) { return 0; };
    hal.can_receive = [](void*, mw_can_frame*) { return 0; };
    hal.time_us = [](void*) { return g_modem->now_us; };
    sink_node_config c{};
    sink_node_default_config(&c);
    c.status_period_s = 0;
    c.config_period_s = 0;
    c.host_count = 2;
    auto sink = std::make_unique<sink_node>();
    ASSERT_EQ(sink_node_init(sink.get(), &hal, &c), MW_OK);
    uint32_t seq = 0;
    for (int ms = 0; ms < 1500; ++ms) {  // host 0 sends a keepalive every 250 ms
        if (ms % 250 == 200 && sink->link == SINK_UPLINK_UP) {
            const mw_keepalive k{250, seq++};
            std::vector<uint8_t> ka(MW_KEEPALIVE_SIZE);
            ASSERT_EQ(mw_keepalive_encode(&k, ka.data(), ka.size()), static_cast<int32_t>(MW_KEEPALIVE_SIZE));
            modem.host_sends(ka);
        }
        sink_node_poll(sink.get());
        modem.now_us += 1000;
    }
    ASSERT_EQ(sink->counters.connects, 1u);
    EXPECT_GE(sink->counters.keepalives_in, 4u);
    for (int ms = 0; ms < 1500; ++ms) {  // then silence
        sink_node_poll(sink.get());
        modem.now_us += 1000;
    }
    EXPECT_EQ(sink->counters.keepalive_timeouts, 1u);
    EXPECT_EQ(sink->counters.connects, 2u);
    EXPECT_NE(std::find(modem.commands.begin(), modem.commands.end(), "AT+CIPSTART=\"TCP\",\"10.0.0.3\",7001"),
              modem.commands.end())
        << "the second host of the list";
}

TEST(EspAtInit, RejectsMissingPieces) {
    fake_modem modem;
    esp_at at{};
    esp_at_serial s = modem.serial();
    esp_at_config c{"a", "b", "h", 0, 0, 0, nullptr, nullptr};
    EXPECT_EQ(esp_at_init(&at, &s, &c), MW_ERR_ARGUMENT) << "port 0";
    c.port = 7000;
    c.more_count = 1;
    EXPECT_EQ(esp_at_init(&at, &s, &c), MW_ERR_ARGUMENT) << "a second host without its address";
    c.more_count = 0;
    c.port = 7000;
    c.baud = 921600;
    s.set_baud = nullptr;
    EXPECT_EQ(esp_at_init(&at, &s, &c), MW_ERR_ARGUMENT) << "baud change without set_baud";
}

}  // namespace
}  // namespace mocap::test
