#include "filter_tool/recording_csv.hpp"

#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <istream>
#include <limits>
#include <ostream>
#include <string_view>

namespace mocap::tools {

namespace {

// Column roles; the header maps each to a position.
enum Col : std::size_t { kT, kGx, kGy, kGz, kAx, kAy, kAz, kMx, kMy, kMz, kQw, kQx, kQy, kQz, kMovement, kColCount };
constexpr std::array<std::string_view, kColCount> kColNames = {"t",  "gx", "gy", "gz", "ax", "ay", "az",      "mx",
                                                               "my", "mz", "qw", "qx", "qy", "qz", "movement"};
constexpr std::size_t kRequired = kQw;  // t..mz are required
constexpr std::size_t kAbsent = static_cast<std::size_t>(-1);

std::string_view trim(std::string_view s) {
    while (!s.empty() && (s.front() == ' ' || s.front() == '\t'))
        s.remove_prefix(1);
    while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r'))
        s.remove_suffix(1);
    return s;
}

std::vector<std::string_view> split(std::string_view line) {
    std::vector<std::string_view> out;
    std::size_t start = 0;
    for (;;) {
        const std::size_t comma = line.find(',', start);
        out.push_back(
            trim(line.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start)));
        if (comma == std::string_view::npos) return out;
        start = comma + 1;
    }
}

// Full-field number (from_chars also accepts "nan" and "inf"); false if anything is left over.
bool parse_double(std::string_view s, double& v) {
    if (s.empty()) return false;
    if (s.front() == '+') s.remove_prefix(1);
    const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    return ec == std::errc() && ptr == s.data() + s.size();
}

CsvError error_at(std::size_t line, std::string message) {
    return CsvError{line, std::move(message)};
}

}  // namespace

std::string CsvError::to_string() const {
    return "line " + std::to_string(line) + ": " + message;
}

std::optional<CsvError> read_recording_csv(std::istream& in, Recording& out) {
    out = Recording{};
    std::string line;
    std::size_t line_no = 0;

    // Header.
    std::array<std::size_t, kColCount> pos{};
    pos.fill(kAbsent);
    std::size_t columns = 0;
    for (;;) {
        if (!std::getline(in, line)) return error_at(line_no + 1, "missing header (file is empty)");
        ++line_no;
        if (!trim(line).empty()) break;
    }
    {
        const auto names = split(line);
        columns = names.size();
        for (std::size_t i = 0; i < names.size(); ++i) {
            for (std::size_t c = 0; c < kColCount; ++c) {
                if (names[i] != kColNames[c]) continue;
                if (pos[c] != kAbsent) return error_at(line_no, "duplicate column '" + std::string(names[i]) + "'");
                pos[c] = i;
            }
        }
        for (std::size_t c = 0; c < kRequired; ++c) {
            if (pos[c] == kAbsent) {
                return error_at(line_no, "missing required column '" + std::string(kColNames[c]) +
                                             "' (header must have t,gx,gy,gz,ax,ay,az,mx,my,mz)");
            }
        }
        const int q_cols =
            (pos[kQw] != kAbsent) + (pos[kQx] != kAbsent) + (pos[kQy] != kAbsent) + (pos[kQz] != kAbsent);
        if (q_cols != 0 && q_cols != 4) return error_at(line_no, "reference needs all of qw,qx,qy,qz");
        out.has_reference = q_cols == 4;
        out.has_movement = pos[kMovement] != kAbsent;
    }

    // Rows.
    std::int64_t last_t_us = 0;
    while (std::getline(in, line)) {
        ++line_no;
        if (trim(line).empty()) continue;
        const auto fields = split(line);
        if (fields.size() != columns) {
            return error_at(line_no,
                            "expected " + std::to_string(columns) + " columns, found " + std::to_string(fields.size()));
        }
        std::array<double, kColCount> v{};
        for (std::size_t c = 0; c < kColCount; ++c) {
            if (pos[c] == kAbsent) continue;
            if (!parse_double(fields[pos[c]], v[c])) {
                return error_at(line_no, "column '" + std::string(kColNames[c]) + "' is not a number: '" +
                                             std::string(fields[pos[c]]) + "'");
            }
        }
        RecordingRow row;
        for (std::size_t c = kT; c <= kAz; ++c) {
            if (!std::isfinite(v[c])) {
                return error_at(line_no, "column '" + std::string(kColNames[c]) + "' must be finite");
            }
        }
        if (v[kT] < 0.0 || v[kT] > 9.2e12) return error_at(line_no, "time out of range");
        row.sample.t_us = std::llround(v[kT] * 1e6);
        if (!out.rows.empty() && row.sample.t_us <= last_t_us) {
            return error_at(line_no, "time does not increase (t = " + std::string(fields[pos[kT]]) +
                                         " s is not after the previous line)");
        }
        last_t_us = row.sample.t_us;
        row.sample.gyro_rad_s = {v[kGx], v[kGy], v[kGz]};
        row.sample.accel_m_s2 = {v[kAx], v[kAy], v[kAz]};
        const bool mag_nan = std::isnan(v[kMx]) || std::isnan(v[kMy]) || std::isnan(v[kMz]);
        if (mag_nan) {
            row.sample.flags |= kImuNoMag;
        } else if (!std::isfinite(v[kMx]) || !std::isfinite(v[kMy]) || !std::isfinite(v[kMz])) {
            return error_at(line_no, "magnetometer must be finite (or nan for no reading)");
        }
        row.sample.mag_ut = {v[kMx], v[kMy], v[kMz]};
        if (out.has_reference) {
            const Quat q(v[kQw], v[kQx], v[kQy], v[kQz]);
            const bool any_nan = std::isnan(v[kQw]) || std::isnan(v[kQx]) || std::isnan(v[kQy]) || std::isnan(v[kQz]);
            if (!any_nan) {
                const double n = q.norm();
                if (!std::isfinite(n) || std::abs(n - 1.0) > 0.01) {
                    return error_at(line_no, "reference quaternion is not unit (norm " + std::to_string(n) + ")");
                }
                row.q_ref = q.normalized();
                row.ref_valid = true;
            }
        }
        if (out.has_movement) {
            if (v[kMovement] != 0.0 && v[kMovement] != 1.0) return error_at(line_no, "movement must be 0 or 1");
            row.movement = v[kMovement] == 1.0;
        }
        out.rows.push_back(row);
    }
    if (in.bad()) return error_at(line_no, "read error");
    if (out.rows.empty()) return error_at(line_no, "no samples after the header");
    return std::nullopt;
}

bool write_recording_csv(std::ostream& out, const Recording& recording) {
    out << "t,gx,gy,gz,ax,ay,az,mx,my,mz";
    if (recording.has_reference) out << ",qw,qx,qy,qz";
    if (recording.has_movement) out << ",movement";
    out << '\n';
    char buf[512];
    for (const RecordingRow& r : recording.rows) {
        const ImuSample& s = r.sample;
        // 9 significant digits hold any sensor's resolution; a missing magnetometer is nan.
        const bool no_mag = !s.has_mag();
        const double nan = std::numeric_limits<double>::quiet_NaN();
        int n = std::snprintf(buf, sizeof buf, "%.6f,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g",
                              static_cast<double>(s.t_us) * 1e-6, s.gyro_rad_s[0], s.gyro_rad_s[1], s.gyro_rad_s[2],
                              s.accel_m_s2[0], s.accel_m_s2[1], s.accel_m_s2[2], no_mag ? nan : s.mag_ut[0],
                              no_mag ? nan : s.mag_ut[1], no_mag ? nan : s.mag_ut[2]);
        out.write(buf, n);
        if (recording.has_reference) {
            const Quat& q = r.q_ref;
            n = r.ref_valid ? std::snprintf(buf, sizeof buf, ",%.12g,%.12g,%.12g,%.12g", q.w(), q.x(), q.y(), q.z())
                            : std::snprintf(buf, sizeof buf, ",nan,nan,nan,nan");
            out.write(buf, n);
        }
        if (recording.has_movement) out << (r.movement ? ",1" : ",0");
        out << '\n';
    }
    return static_cast<bool>(out);
}

bool write_orientation_csv(std::ostream& out, const std::vector<OrientationRow>& rows) {
    out << "t,qw,qx,qy,qz\n";
    char buf[160];
    for (const OrientationRow& r : rows) {
        const int n = std::snprintf(buf, sizeof buf, "%.6f,%.12g,%.12g,%.12g,%.12g\n",
                                    static_cast<double>(r.t_us) * 1e-6, r.q.w(), r.q.x(), r.q.y(), r.q.z());
        out.write(buf, n);
    }
    return static_cast<bool>(out);
}

}  // namespace mocap::tools
