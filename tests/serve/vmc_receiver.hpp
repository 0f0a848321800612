// vmc_receiver.hpp — the VMC tests' receiver: liblo decodes what arrives (from bytes, or on a
// UDP port of its own) and keeps every message's address and arguments.
#pragma once

#include <lo/lo.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <mutex>
#include <string>
#include <vector>

namespace mocap::serve {

struct OscMessage {
    std::string path;
    std::string types;
    std::string name;           ///< the first argument when it is a string
    std::vector<float> floats;  ///< every float argument in order
    std::vector<std::int32_t> ints;
};

class VmcReceiver {
public:
    /// On a free UDP port that liblo picks.
    VmcReceiver() {
        server_ = lo_server_new_with_proto(nullptr, LO_UDP, nullptr);
        if (server_ != nullptr) lo_server_add_method(server_, nullptr, nullptr, &VmcReceiver::on_message, this);
    }
    ~VmcReceiver() {
        if (server_ != nullptr) lo_server_free(server_);
    }
    VmcReceiver(const VmcReceiver&) = delete;
    VmcReceiver& operator=(const VmcReceiver&) = delete;

    [[nodiscard]] bool ok() const { return server_ != nullptr; }
    [[nodiscard]] int port() const { return lo_server_get_port(server_); }
    /// Decodes one OSC packet (a bundle or a message).
    void dispatch(const std::vector<char>& bytes) {
        lo_server_dispatch_data(server_, const_cast<char*>(bytes.data()), bytes.size());
    }
    /// Reads whatever arrived on the port, without waiting. Returns the packets read.
    int poll() {
        int packets = 0;
        while (lo_server_recv_noblock(server_, 0) > 0)
            ++packets;
        return packets;
    }
    std::vector<OscMessage> messages;

private:
    static int on_message(const char* path, const char* types, lo_arg** argv, int argc, lo_message /*msg*/,
                          void* self) {
        OscMessage m;
        m.path = path;
        m.types = types;
        // liblo hands each argument as an lo_arg* into the packet, 4-byte aligned only: read
        // the bytes, never the 8-byte-aligned union's members (UBSan: misaligned access).
        for (int i = 0; i < argc; ++i) {
            const char* at = reinterpret_cast<const char*>(argv[i]);
            if (types[i] == LO_STRING && i == 0) m.name = at;
            if (types[i] == LO_FLOAT) {
                float v = 0.0F;
                std::memcpy(&v, at, sizeof v);
                m.floats.push_back(v);
            }
            if (types[i] == LO_INT32) {
                std::int32_t v = 0;
                std::memcpy(&v, at, sizeof v);
                m.ints.push_back(v);
            }
        }
        static_cast<VmcReceiver*>(self)->messages.push_back(std::move(m));
        return 0;
    }
    lo_server server_ = nullptr;
};

}  // namespace mocap::serve
