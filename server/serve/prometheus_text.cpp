// prometheus_text.cpp — naming rules and the text format; see the header for the rules.
#include "serve/prometheus_text.hpp"

#include <spdlog/fmt/fmt.h>

#include <cmath>
#include <map>

namespace mocap::serve {

namespace {

// Lower case, [a-z0-9_] only, no doubled or edge underscores.
std::string sanitize(std::string_view in) {
    std::string out;
    for (const char raw : in) {
        char c = raw;
        if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
        const bool ok = (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9');
        if (!ok) c = '_';
        if (c == '_' && (out.empty() || out.back() == '_')) continue;
        out += c;
    }
    while (!out.empty() && out.back() == '_')
        out.pop_back();
    return out;
}

std::vector<std::string> split_tokens(const std::string& s) {
    std::vector<std::string> tokens;
    std::size_t start = 0;
    while (start <= s.size()) {
        const std::size_t end = s.find('_', start);
        const std::size_t stop = end == std::string::npos ? s.size() : end;
        if (stop > start) tokens.push_back(s.substr(start, stop - start));
        if (end == std::string::npos) break;
        start = end + 1;
    }
    return tokens;
}

// A value as Prometheus reads it: integers exactly, others with full precision.
std::string number(double v) {
    if (std::isnan(v)) return "NaN";
    if (std::isinf(v)) return v > 0 ? "+Inf" : "-Inf";
    if (v == std::floor(v) && std::abs(v) < 1e15) return fmt::format("{:.0f}", v);
    return fmt::format("{}", v);
}

std::string escape_label(std::string_view v) {
    std::string out;
    for (const char c : v) {
        if (c == '\\' || c == '"') out += '\\';
        if (c == '\n') {
            out += "\\n";
            continue;
        }
        out += c;
    }
    return out;
}

void family(std::string& out, const std::string& name, const char* type, std::string_view help) {
    fmt::format_to(std::back_inserter(out), "# HELP {} {}\n# TYPE {} {}\n", name, help, name, type);
}

}  // namespace

std::string prometheus_counter_name(std::string_view dotted, double* divisor) {
    *divisor = 1.0;
    std::vector<std::string> tokens = split_tokens(sanitize(dotted));
    if (!tokens.empty() && tokens.back() == "total") tokens.pop_back();
    std::string unit;
    for (auto it = tokens.begin(); it != tokens.end();) {
        if (*it == "bytes") {
            unit = "bytes";
        } else if (*it == "us") {
            unit = "seconds";
            *divisor = 1e6;
        } else if (*it == "ms") {
            unit = "seconds";
            *divisor = 1e3;
        } else if (*it == "seconds") {
            unit = "seconds";
        } else {
            ++it;
            continue;
        }
        it = tokens.erase(it);
    }
    std::string name = "mocapd";
    for (const auto& t : tokens)
        name += "_" + t;
    if (!unit.empty()) name += "_" + unit;
    return name + "_total";
}

std::string render_prometheus(const MetricsSnapshot& snapshot) {
    std::string out;
    out.reserve(16384);

    // Counters: merged by Prometheus name, listed in name order (stable output).
    struct Family {
        double value = 0;
        std::vector<std::string> sources;
    };
    std::map<std::string, Family> counters;
    for (const CounterValue& c : snapshot.counters) {
        double divisor = 1.0;
        Family& f = counters[prometheus_counter_name(c.name, &divisor)];
        f.value += static_cast<double>(c.value) / divisor;  // exact decimals, unlike * 1e-6
        f.sources.push_back(c.name);
    }
    for (const auto& [name, f] : counters) {
        std::string help = "mocapd counter";
        for (std::size_t i = 0; i < f.sources.size(); ++i)
            help += (i == 0 ? " " : " + ") + f.sources[i];
        family(out, name, "counter", help);
        fmt::format_to(std::back_inserter(out), "{} {}\n", name, number(f.value));
    }

    std::map<std::string, const GaugeValue*> gauges;
    for (const GaugeValue& g : snapshot.gauges)
        gauges["mocapd_" + sanitize(g.name)] = &g;
    for (const auto& [name, g] : gauges) {
        family(out, name, "gauge", g->help);
        fmt::format_to(std::back_inserter(out), "{} {}\n", name, number(g->value));
    }

    if (!snapshot.latencies.empty()) {
        const std::string name = "mocapd_stage_latency_seconds";
        family(out, name, "histogram",
               "Latency of each pipeline stage in seconds (wall clock; ingest = sink send to "
               "host receive)");
        for (const LatencyValue& l : snapshot.latencies) {
            const std::string stage = escape_label(l.stage);
            const LatencySnapshot& s = l.snapshot;
            std::size_t bucket = 0;
            std::uint64_t cumulative = 0;
            for (const double le_s : kLatencyBucketsS) {
                const auto le_us = static_cast<std::uint64_t>(std::llround(le_s * 1e6));
                while (bucket < kLatencyBuckets && latency_bucket_upper_us(bucket) <= le_us) {
                    cumulative += s.buckets[bucket++];
                }
                fmt::format_to(std::back_inserter(out), "{}_bucket{{stage=\"{}\",le=\"{}\"}} {}\n", name, stage,
                               number(le_s), cumulative);
            }
            fmt::format_to(std::back_inserter(out), "{}_bucket{{stage=\"{}\",le=\"+Inf\"}} {}\n", name, stage, s.count);
            fmt::format_to(std::back_inserter(out), "{}_sum{{stage=\"{}\"}} {}\n", name, stage,
                           number(static_cast<double>(s.sum_us) / 1e6));
            fmt::format_to(std::back_inserter(out), "{}_count{{stage=\"{}\"}} {}\n", name, stage, s.count);
        }
        const std::string neg = "mocapd_stage_latency_negative_total";
        family(out, neg, "counter",
               "Stage latencies below zero (a sender's clock ahead of the host's), not in the histogram");
        for (const LatencyValue& l : snapshot.latencies) {
            fmt::format_to(std::back_inserter(out), "{}{{stage=\"{}\"}} {}\n", neg, escape_label(l.stage),
                           l.snapshot.negative);
        }
    }
    return out;
}

}  // namespace mocap::serve
