// stream_uplink.hpp — the POSIX TCP uplink of a simulated sink (the sink_node HAL's uplink_*).
//
// Non-blocking socket with TCP_NODELAY. connect() starts an attempt (completion is seen by
// state()); write() takes a whole packet or nothing: when the kernel accepts only part of
// it, the rest is kept and sent first at the next state()/write(), and while such a rest
// is pending a new packet is refused as busy. A peer that closes the connection shows as
// DOWN at the next state() (checked with a non-blocking peek). Reconnect pacing and the
// choice of host are the sink core's (back-off, ordered host list): connect(host) dials the
// host-th address given at construction. read() hands the core what the daemon sends (its
// keepalives, docs/protocol.md §3.5) without blocking.
//
// Ownership: owns its socket; closes it on destruction. Thread-safety: one thread.
// Cost: state() is one poll()/recv() system call; write() one send().
#pragma once

#include <netinet/in.h>

#include <cstdint>
#include <string>
#include <vector>

#include "sink_node/sink_node.h"

namespace mocap::sim {

class PosixUplink {
public:
    /// `peers`: the ordered host list, resolved (resolve_ipv4); at least one.
    explicit PosixUplink(std::vector<sockaddr_in> peers);
    ~PosixUplink();
    PosixUplink(const PosixUplink&) = delete;
    PosixUplink& operator=(const PosixUplink&) = delete;

    int connect(std::uint8_t host);
    /// Bytes the daemon sent, up to cap: >= 0 read (0 = none now), -1 = closed or failed.
    int read(std::uint8_t* data, std::size_t cap);
    sink_uplink_state state();
    int write(const std::uint8_t* data, std::size_t len);
    void close();

    /// Bytes the kernel accepted so far.
    [[nodiscard]] std::uint64_t bytes_sent() const { return bytes_sent_; }

private:
    bool flush_pending();

    std::vector<sockaddr_in> peers_;
    int fd_ = -1;
    sink_uplink_state state_ = SINK_UPLINK_DOWN;
    std::vector<std::uint8_t> pending_;
    std::size_t pending_offset_ = 0;
    std::uint64_t bytes_sent_ = 0;
};

/// "HOST:PORT" (HOST a name or IPv4 address) -> address; false with *error set otherwise.
bool resolve_ipv4(const std::string& host_port, sockaddr_in* out, std::string* error);
/// "HOST:PORT[,HOST:PORT...]" -> the ordered host list (1..max entries); false with *error.
bool resolve_host_list(const std::string& list, std::size_t max, std::vector<sockaddr_in>* out, std::string* error);

}  // namespace mocap::sim
