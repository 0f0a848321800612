// framing.hpp — length-delimited messages: a base-128 varint length, then that many
// bytes of one protobuf message (protobuf's writeDelimitedTo/parseDelimitedFrom framing).
//
// Used by the server's client sessions and by the client library alike. No I/O, no
// clock, no Asio. DelimitedReader is an incremental decoder: bytes arrive in any split
// (one byte at a time is fine) and complete messages come out.
//
// Thread-safety: none; one reader per connection.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace google::protobuf {
class MessageLite;
}

namespace mocap::serve {

/// Longest varint a length may use: lengths are at most 32 bits, i.e. 5 bytes.
inline constexpr std::size_t kMaxLengthPrefixBytes = 5;

/// Writes `value` as a varint to `out` (room for 10 bytes); returns the bytes written.
std::size_t write_varint(std::uint64_t value, std::uint8_t* out);

/// Appends `message`, length-prefixed, to `out`. Returns false if it cannot be serialised.
bool append_delimited(const google::protobuf::MessageLite& message, std::string& out);

enum class FrameStatus {
    kNeedMore,   ///< no complete message yet; read more bytes
    kMessage,    ///< `payload` holds one message
    kTooLarge,   ///< the prefix announces more than max_message_bytes: close the connection
    kBadPrefix,  ///< the prefix is longer than 5 bytes or above 32 bits: garbage
};

struct FrameResult {
    FrameStatus status = FrameStatus::kNeedMore;
    std::span<const std::uint8_t> payload{};  ///< valid until the next write_area()/next()
};

class DelimitedReader {
public:
    /// `max_message_bytes` bounds one message (the prefix is not counted). The buffer
    /// grows on demand up to max_message_bytes + 5 and never beyond.
    explicit DelimitedReader(std::size_t max_message_bytes);

    /// Free space to receive into (never empty while no error was returned). Moves
    /// unconsumed bytes to the front when needed.
    std::span<std::uint8_t> write_area();
    /// `n` bytes of write_area() were filled.
    void commit(std::size_t n);
    /// The next complete message, if any. After kTooLarge/kBadPrefix the reader stays
    /// in that state: the stream cannot be resynchronised.
    FrameResult next();

    /// Bytes received but not yet returned as messages.
    [[nodiscard]] std::size_t buffered() const { return end_ - begin_; }
    [[nodiscard]] std::size_t max_message_bytes() const { return max_message_bytes_; }

private:
    std::size_t max_message_bytes_;
    std::vector<std::uint8_t> buf_;
    std::size_t begin_ = 0;                       ///< first unconsumed byte
    std::size_t end_ = 0;                         ///< one past the last received byte
    FrameStatus error_ = FrameStatus::kNeedMore;  ///< sticky kTooLarge/kBadPrefix
};

}  // namespace mocap::serve
