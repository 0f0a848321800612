// socketcan_reader.hpp — reads one Linux SocketCAN interface (can0, vcan0, ...) directly.
//
// A raw CAN socket bound to the interface, non-blocking, driven by Asio
// (posix::stream_descriptor::async_wait, then recvmsg until EAGAIN). CAN FD is enabled on
// the socket (CAN_RAW_FD_FRAMES) so FD-capable interfaces deliver classic frames too; FD
// frames with more than 8 bytes are not part of the body network and are counted as
// malformed. Every frame carries the kernel's receive timestamp (SO_TIMESTAMP, wall clock
// µs), used as the sample time base; the kernel's receive-queue drop counter
// (SO_RXQ_OVFL) is surfaced as `kernel_drops`. Error frames and RTR frames are counted and
// ignored. Frames go to one FrameReassembler whose subject is given by the config.
//
// Threading: runs on the io_context passed in (the single ingest thread). counters() may be
// read from any thread; they are SingleWriterCounter, written only on that thread.
// Cost: one recvmsg per frame; no allocation after open().
#pragma once

#include <cstdint>
#include <string>

#include "core/asio.hpp"
#include "core/clock.hpp"
#include "core/counters.hpp"
#include "core/metrics_registry.hpp"
#include "ingest/frame_reassembler.hpp"

namespace mocap::ingest {

struct SocketCanConfig {
    std::string interface = "can0";
    std::uint32_t subject = 1;
    FrameReassembler::Params reassembly{};
};

class SocketCanReader {
public:
    SocketCanReader(asio::io_context& io, SocketCanConfig config, const Clock& clock, SampleSink sink);
    ~SocketCanReader();

    SocketCanReader(const SocketCanReader&) = delete;
    SocketCanReader& operator=(const SocketCanReader&) = delete;

    /// Opens and binds the socket and starts reading. Returns false with a message naming
    /// the interface if the kernel has no CAN support, the interface does not exist, etc.
    bool start(std::string* error);
    void stop();

    [[nodiscard]] const SocketCanConfig& config() const { return config_; }
    /// Component "ingest_can:<interface>": frames_read, fd_frames, error_frames, rtr_frames,
    /// foreign_frames, kernel_drops, read_errors, plus the reassembly counters.
    [[nodiscard]] const CounterGroup& counters() const { return group_; }
    /// Set-up: the counters above.
    void register_metrics(MetricsRegistry& registry) const { registry.add(group_); }

private:
    void do_wait();
    void on_readable(const boost::system::error_code& ec);
    void read_all();

    SocketCanConfig config_;
    const Clock& clock_;
    asio::posix::stream_descriptor socket_;
    ReassemblyCounters reassembly_;
    FrameReassembler reassembler_;
    std::uint32_t last_kernel_drops_ = 0;
    bool stopped_ = false;
    SingleWriterCounter frames_read_, fd_frames_, error_frames_, rtr_frames_, foreign_frames_, kernel_drops_,
        read_errors_;
    CounterGroup group_;
};

}  // namespace mocap::ingest
