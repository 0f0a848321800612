#include "daemon/replay_args.hpp"

#include <algorithm>
#include <ctime>

#include "core/parse_number.hpp"

namespace mocap::daemon {

namespace {

bool is_digits(std::string_view s) {
    return !s.empty() && std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

/// "SSS" or "SSS.ffffff" (digits only; up to 6 fraction digits count) → µs.
bool parse_epoch_us(std::string_view text, std::int64_t* us) {
    const std::size_t dot = text.find('.');
    const std::string_view whole = text.substr(0, dot);
    const std::string_view frac = dot == std::string_view::npos ? std::string_view{} : text.substr(dot + 1);
    std::int64_t seconds = 0;
    if (!is_digits(whole) || !core::parse_number(whole, seconds) || seconds > 1'000'000'000'000) return false;
    if (dot != std::string_view::npos && !is_digits(frac)) return false;
    std::int64_t frac_us = 0;
    for (std::size_t i = 0; i < 6; ++i)
        frac_us = frac_us * 10 + (i < frac.size() ? frac[i] - '0' : 0);
    *us = seconds * 1'000'000 + frac_us;
    return true;
}

/// RFC 3339 date-time: YYYY-MM-DDTHH:MM:SS[.frac](Z|+HH:MM|-HH:MM) → µs since the epoch.
bool parse_rfc3339_us(std::string_view t, std::int64_t* us) {
    auto num = [&](std::size_t at, std::size_t n, int* out) {
        return at + n <= t.size() && is_digits(t.substr(at, n)) && core::parse_number(t.substr(at, n), *out);
    };
    int year = 0, month = 0, day = 0, hour = 0, minute = 0, second = 0;
    if (t.size() < 20 || !num(0, 4, &year) || t[4] != '-' || !num(5, 2, &month) || t[7] != '-' || !num(8, 2, &day) ||
        (t[10] != 'T' && t[10] != 't' && t[10] != ' ') || !num(11, 2, &hour) || t[13] != ':' || !num(14, 2, &minute) ||
        t[16] != ':' || !num(17, 2, &second))
        return false;
    if (month < 1 || month > 12 || day < 1 || day > 31 || hour > 23 || minute > 59 || second > 60) return false;
    std::size_t i = 19;
    std::int64_t frac_us = 0;
    if (t[i] == '.') {
        const std::size_t start = ++i;
        while (i < t.size() && t[i] >= '0' && t[i] <= '9')
            ++i;
        if (i == start || !parse_epoch_us("0" + std::string(t.substr(start - 1, i - start + 1)), &frac_us))
            return false;
    }
    std::int64_t offset_s = 0;
    if (i < t.size() && (t[i] == 'Z' || t[i] == 'z')) {
        ++i;
    } else if (i < t.size() && (t[i] == '+' || t[i] == '-')) {
        int oh = 0, om = 0;
        if (!num(i + 1, 2, &oh) || i + 3 >= t.size() || t[i + 3] != ':' || !num(i + 4, 2, &om) || oh > 23 || om > 59)
            return false;
        offset_s = (t[i] == '-' ? -1 : 1) * (static_cast<std::int64_t>(oh) * 3600 + static_cast<std::int64_t>(om) * 60);
        i += 6;
    } else {
        return false;  // RFC 3339 requires the offset
    }
    if (i != t.size()) return false;
    std::tm tm{};
    tm.tm_year = year - 1900;
    tm.tm_mon = month - 1;
    tm.tm_mday = day;
    tm.tm_hour = hour;
    tm.tm_min = minute;
    tm.tm_sec = second;
    const std::time_t utc = timegm(&tm);
    *us = (static_cast<std::int64_t>(utc) - offset_s) * 1'000'000 + frac_us;
    return true;
}

}  // namespace

bool parse_replay_time(std::string_view text, std::int64_t* us, std::string* error) {
    if (parse_epoch_us(text, us) || parse_rfc3339_us(text, us)) return true;
    *error = "time " + std::string(text) +
             ": expected seconds since the epoch (e.g. 1764648000.25) or RFC 3339 (e.g. 2026-12-02T04:10:00Z)";
    return false;
}

bool parse_replay_calibration(std::string_view spec, ReplayCalibration* out, std::string* error) {
    const auto f = core::split_fields(spec, ':');
    ReplayCalibration c;
    bool ok = f.size() <= 3 && core::parse_number(f[0], c.at_s) && c.at_s >= 0.0;
    if (ok && f.size() >= 2) ok = core::parse_number(f[1], c.subject) && c.subject >= 1;
    if (ok && f.size() == 3) {
        if (f[2] == "N" || f[2] == "n")
            c.pose = skeleton::CalibrationPose::kNPose;
        else
            ok = f[2] == "T" || f[2] == "t";
    }
    if (!ok) {
        *error = "--calibrate-at " + std::string(spec) +
                 ": expected SECONDS[:SUBJECT[:T|N]] with SECONDS >= 0 and SUBJECT >= 1";
        return false;
    }
    *out = c;
    return true;
}

}  // namespace mocap::daemon
