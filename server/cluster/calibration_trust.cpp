#include "cluster/calibration_trust.hpp"

#include <fcntl.h>
#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cmath>

#include "core/errno_text.hpp"

namespace mocap::cluster {
namespace {

/// A key file never needs more.
constexpr std::size_t kMaxKeyFileBytes = 4096;
/// How far q_world_earth may be from the heading turn it must be (rounding in the text form
/// is ~1e-16; a tilt of a degree is a different world).
constexpr double kMaxWorldTiltRad = 1.0 * M_PI / 180.0;

std::string trimmed(const std::string& s) {
    const auto first = s.find_first_not_of(" \t\r\n");
    if (first == std::string::npos) return {};
    const auto last = s.find_last_not_of(" \t\r\n");
    return s.substr(first, last - first + 1);
}

std::string message(const SignedFields& f) {
    return "mocap-calibration/1\n" + f.site + "\n" + std::to_string(f.subject) + "\n" + f.host_id + "\n" +
           std::to_string(f.time_us) + "\n" + f.calibration_text;
}

double angle_between(const skeleton::Quat& a, const skeleton::Quat& b) {
    const double d = std::min(1.0, std::abs(a.normalized().dot(b.normalized())));
    return 2.0 * std::acos(d);
}

}  // namespace

std::optional<std::string> read_calibration_key(const std::string& path, std::string* error) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
    if (fd < 0) {
        *error = "cannot read " + path + ": " + errno_text(errno);
        return std::nullopt;
    }
    std::string text;
    struct stat st {};
    std::string problem;
    if (::fstat(fd, &st) != 0) {
        problem = errno_text(errno);
    } else if (!S_ISREG(st.st_mode)) {
        problem = "not a regular file";
    } else if ((st.st_mode & (S_IRWXO | S_IWGRP)) != 0) {
        problem = "others may read or write it, or its group may write it (mode " +
                  std::to_string((st.st_mode >> 6) & 7) + std::to_string((st.st_mode >> 3) & 7) +
                  std::to_string(st.st_mode & 7) + "; chmod 0600 or 0640)";
    } else {
        std::array<char, kMaxKeyFileBytes + 1> buf{};
        ssize_t n = 0;
        do {
            n = ::read(fd, buf.data(), buf.size());
        } while (n < 0 && errno == EINTR);
        if (n < 0) {
            problem = errno_text(errno);
        } else if (static_cast<std::size_t>(n) > kMaxKeyFileBytes) {
            problem = "longer than " + std::to_string(kMaxKeyFileBytes) + " bytes";
        } else {
            text = trimmed(std::string(buf.data(), static_cast<std::size_t>(n)));
            if (text.size() < kMinCalibrationKeyBytes)
                problem = "the key is " + std::to_string(text.size()) + " bytes, at least " +
                          std::to_string(kMinCalibrationKeyBytes) + " needed (e.g. `head -c 32 /dev/urandom | base64`)";
        }
    }
    ::close(fd);
    if (!problem.empty()) {
        *error = path + ": " + problem;
        return std::nullopt;
    }
    return text;
}

std::string calibration_signature(const std::string& key, const SignedFields& fields) {
    const std::string m = message(fields);
    std::array<unsigned char, EVP_MAX_MD_SIZE> mac{};
    unsigned int len = 0;
    if (HMAC(EVP_sha256(), key.data(), static_cast<int>(key.size()), reinterpret_cast<const unsigned char*>(m.data()),
             m.size(), mac.data(), &len) == nullptr)
        return {};
    static constexpr char kHex[] = "0123456789abcdef";
    std::string hex;
    hex.reserve(2 * static_cast<std::size_t>(len));
    for (unsigned int i = 0; i < len; ++i) {
        hex += kHex[mac[i] >> 4];
        hex += kHex[mac[i] & 15];
    }
    return hex;
}

bool signature_matches(const std::string& key, const SignedFields& fields, const std::string& signature) {
    const std::string expected = calibration_signature(key, fields);
    return !expected.empty() && signature.size() == expected.size() &&
           CRYPTO_memcmp(signature.data(), expected.data(), expected.size()) == 0;
}

std::string implausible_calibration(const skeleton::Calibration& c) {
    if (c.pose != skeleton::CalibrationPose::kTPose && c.pose != skeleton::CalibrationPose::kNPose)
        return "not taken in a T- or N-pose";
    if (!std::isfinite(c.facing_heading_rad)) return "facing heading is not finite";
    const skeleton::Quat turn(std::cos(0.5 * c.facing_heading_rad), 0.0, 0.0, std::sin(0.5 * c.facing_heading_rad));
    const skeleton::Quat expected =
        c.heading_mode == skeleton::HeadingMode::kAlignToForward ? turn.conjugate() : skeleton::Quat::Identity();
    const double off = angle_between(c.q_world_earth, expected);
    if (!(off <= kMaxWorldTiltRad))
        return "q_world_earth is " + std::to_string(off * 180.0 / M_PI) +
               " deg from the heading turn of its heading mode: the body would not stand upright";
    return {};
}

}  // namespace mocap::cluster
