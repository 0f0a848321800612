#include "ingest/socketcan_reader.hpp"

#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <spdlog/spdlog.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "core/errno_text.hpp"

namespace mocap::ingest {

using boost::system::error_code;

SocketCanReader::SocketCanReader(asio::io_context& io, SocketCanConfig config, const Clock& clock, SampleSink sink)
    : config_(std::move(config)),
      clock_(clock),
      socket_(io),
      reassembler_(config_.subject, config_.reassembly, reassembly_, std::move(sink)),
      group_("ingest_can:" + config_.interface) {
    group_.add("frames_read", frames_read_);
    group_.add("fd_frames", fd_frames_);
    group_.add("error_frames", error_frames_);
    group_.add("rtr_frames", rtr_frames_);
    group_.add("foreign_frames", foreign_frames_);
    group_.add("kernel_drops", kernel_drops_);
    group_.add("read_errors", read_errors_);
    reassembly_.register_in(group_);
}

SocketCanReader::~SocketCanReader() {
    stop();
}

bool SocketCanReader::start(std::string* error) {
    const auto fail = [&](const std::string& what) {
        *error = "socketcan " + config_.interface + ": " + what + ": " + errno_text(errno);
        return false;
    };
    const int fd = ::socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
    if (fd < 0) return fail("socket(PF_CAN) (is the kernel's can-raw module loaded?)");
    // From here the descriptor belongs to socket_, which closes it on every path.
    socket_.assign(fd);
    const int on = 1;
    // FD-capable interfaces: accept both classic and FD frames on this socket. Not fatal:
    // a kernel without CAN FD still delivers classic frames.
    ::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof on);
    if (::setsockopt(fd, SOL_SOCKET, SO_TIMESTAMP, &on, sizeof on) < 0) return fail("SO_TIMESTAMP");
    if (::setsockopt(fd, SOL_SOCKET, SO_RXQ_OVFL, &on, sizeof on) < 0) return fail("SO_RXQ_OVFL");
    const can_err_mask_t err_mask = CAN_ERR_MASK;  // count bus errors too
    ::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &err_mask, sizeof err_mask);
    const unsigned index = ::if_nametoindex(config_.interface.c_str());
    if (index == 0) return fail("no such interface");
    sockaddr_can addr{};
    addr.can_family = AF_CAN;
    addr.can_ifindex = static_cast<int>(index);
    if (::bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) < 0) return fail("bind");
    spdlog::info("socketcan {}: reading (subject {})", config_.interface, config_.subject);
    do_wait();
    return true;
}

void SocketCanReader::stop() {
    if (stopped_) return;
    stopped_ = true;
    error_code ec;
    socket_.cancel(ec);
    socket_.close(ec);
}

void SocketCanReader::do_wait() {
    socket_.async_wait(asio::posix::stream_descriptor::wait_read, [this](const error_code& ec) { on_readable(ec); });
}

void SocketCanReader::on_readable(const error_code& ec) {
    if (ec == asio::error::operation_aborted || stopped_) return;
    if (ec) {
        read_errors_.add();
        spdlog::error("socketcan {}: wait: {}", config_.interface, ec.message());
        return;
    }
    read_all();
    if (!stopped_) do_wait();
}

void SocketCanReader::read_all() {
    const int fd = socket_.native_handle();
    for (;;) {
        canfd_frame frame{};
        iovec iov{&frame, sizeof frame};
        alignas(cmsghdr) char control[CMSG_SPACE(sizeof(timeval)) + CMSG_SPACE(sizeof(std::uint32_t))];
        msghdr msg{};
        msg.msg_iov = &iov;
        msg.msg_iovlen = 1;
        msg.msg_control = control;
        msg.msg_controllen = sizeof control;
        const ssize_t n = ::recvmsg(fd, &msg, MSG_DONTWAIT);
        if (n < 0) {
            if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) return;
            read_errors_.add();
            spdlog::error("socketcan {}: recvmsg: {}", config_.interface, errno_text(errno));
            return;
        }
        const std::int64_t received_us = clock_.now_us();
        std::int64_t kernel_us = received_us;
        for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c != nullptr; c = CMSG_NXTHDR(&msg, c)) {
            if (c->cmsg_level != SOL_SOCKET) continue;
            if (c->cmsg_type == SO_TIMESTAMP) {
                timeval tv{};
                std::memcpy(&tv, CMSG_DATA(c), sizeof tv);
                kernel_us = static_cast<std::int64_t>(tv.tv_sec) * 1'000'000 + tv.tv_usec;
            } else if (c->cmsg_type == SO_RXQ_OVFL) {
                std::uint32_t drops = 0;
                std::memcpy(&drops, CMSG_DATA(c), sizeof drops);
                // The kernel reports a running total for the socket.
                if (drops > last_kernel_drops_) kernel_drops_.add(drops - last_kernel_drops_);
                last_kernel_drops_ = drops;
            }
        }
        frames_read_.add();
        if (static_cast<std::size_t>(n) == CANFD_MTU) fd_frames_.add();
        if ((frame.can_id & CAN_ERR_FLAG) != 0) {
            error_frames_.add();
            continue;
        }
        if ((frame.can_id & CAN_RTR_FLAG) != 0) {
            rtr_frames_.add();
            continue;
        }
        if (frame.len > 8 || (frame.can_id & CAN_EFF_FLAG) != 0) {
            foreign_frames_.add();  // FD payloads and 29-bit IDs are not ours
            continue;
        }
        mw_can_frame f{};
        f.id = static_cast<std::uint16_t>(frame.can_id & CAN_SFF_MASK);
        f.dlc = frame.len;
        std::memcpy(f.data, frame.data, frame.len);
        // No sink on this path: the kernel receive time stands in for the "sink send" stamp.
        reassembler_.on_frame(f, kernel_us, kernel_us, received_us);
    }
}

}  // namespace mocap::ingest
