// framing.cpp — varint length prefix encoding and the incremental reader.
#include "serve/framing.hpp"

#include <google/protobuf/message_lite.h>

#include <algorithm>
#include <cstring>

namespace mocap::serve {

std::size_t write_varint(std::uint64_t value, std::uint8_t* out) {
    std::size_t n = 0;
    while (value >= 0x80u) {
        out[n++] = static_cast<std::uint8_t>(value | 0x80u);
        value >>= 7;
    }
    out[n++] = static_cast<std::uint8_t>(value);
    return n;
}

bool append_delimited(const google::protobuf::MessageLite& message, std::string& out) {
    const std::size_t size = message.ByteSizeLong();
    if (size > 0xFFFFFFFFu) return false;
    std::uint8_t prefix[10];
    const std::size_t prefix_len = write_varint(size, prefix);
    const std::size_t at = out.size();
    out.resize(at + prefix_len + size);
    std::memcpy(out.data() + at, prefix, prefix_len);
    // ByteSizeLong() above cached the sizes, so serialisation does not walk twice.
    auto* dst = reinterpret_cast<std::uint8_t*>(out.data() + at + prefix_len);
    return message.SerializeWithCachedSizesToArray(dst) == dst + size;
}

DelimitedReader::DelimitedReader(std::size_t max_message_bytes) : max_message_bytes_(max_message_bytes) {
    // Start small; a server-side reader (max a few KiB) reaches its full size at once.
    buf_.resize(std::min<std::size_t>(max_message_bytes + kMaxLengthPrefixBytes, std::size_t{64} * 1024));
}

std::span<std::uint8_t> DelimitedReader::write_area() {
    if (begin_ == end_) begin_ = end_ = 0;
    if (end_ == buf_.size()) {
        if (begin_ > 0) {
            std::memmove(buf_.data(), buf_.data() + begin_, end_ - begin_);
            end_ -= begin_;
            begin_ = 0;
        } else {
            // A message longer than the buffer but within the limit is arriving: grow.
            const std::size_t limit = max_message_bytes_ + kMaxLengthPrefixBytes;
            buf_.resize(std::min(limit, std::max<std::size_t>(buf_.size() * 2, 1024)));
        }
    }
    return {buf_.data() + end_, buf_.size() - end_};
}

void DelimitedReader::commit(std::size_t n) {
    end_ = std::min(end_ + n, buf_.size());
}

FrameResult DelimitedReader::next() {
    if (error_ != FrameStatus::kNeedMore) return {error_, {}};
    std::uint64_t length = 0;
    std::size_t i = 0;
    for (;; ++i) {
        if (i == kMaxLengthPrefixBytes) {
            error_ = FrameStatus::kBadPrefix;
            return {error_, {}};
        }
        if (begin_ + i == end_) return {};  // prefix incomplete
        const std::uint8_t byte = buf_[begin_ + i];
        length |= static_cast<std::uint64_t>(byte & 0x7Fu) << (7 * i);
        if ((byte & 0x80u) == 0) break;
    }
    if (length > 0xFFFFFFFFu) {
        error_ = FrameStatus::kBadPrefix;
        return {error_, {}};
    }
    if (length > max_message_bytes_) {
        error_ = FrameStatus::kTooLarge;
        return {error_, {}};
    }
    const std::size_t prefix_len = i + 1;
    if (end_ - begin_ < prefix_len + length) {
        // Make sure the whole message will fit once more bytes arrive.
        if (buf_.size() - begin_ < prefix_len + length && begin_ == 0) {
            buf_.resize(std::max(buf_.size(), static_cast<std::size_t>(prefix_len + length)));
        }
        return {};
    }
    const std::uint8_t* payload = buf_.data() + begin_ + prefix_len;
    begin_ += prefix_len + length;
    return {FrameStatus::kMessage, {payload, static_cast<std::size_t>(length)}};
}

}  // namespace mocap::serve
