#include "daemon/config.hpp"

#include <toml++/toml.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "daemon/config_table_reader.hpp"

namespace mocap::daemon {
namespace {

void read_log(TableReader& r, DaemonConfig& c) {
    r.read("level", c.log_level);
    static const std::set<std::string> levels{"trace", "debug", "info", "warn", "error", "off"};
    if (!levels.count(c.log_level)) {
        r.fail("level", r.take("level"), "must be one of trace, debug, info, warn, error, off");
    }
    r.read_zero_or("stats_interval_s", c.stats_interval_s, 0.1, 86400.0);
}

void read_ingest(TableReader& r, DaemonConfig& c) {
    r.read("sink_listen", c.sink_listen);
    r.read("max_sinks", c.max_sinks, 1, 4096);
    r.read("sink_idle_timeout_s", c.sink_idle_timeout_s, 0.1, 3600.0);
    r.read("subject_id_base", c.subject_id_base, 0, kMaxSubjectIdBase);
    r.read_zero_or("keepalive_period_s", c.keepalive_period_s, 0.02, 60.0);
    if (const auto* arr = r.array("socketcan")) {
        for (const auto& item : *arr) {
            if (!item.is_table()) r.fail("socketcan", &item, "expected [[ingest.socketcan]] tables");
            TableReader t(*item.as_table(), r.key_path("socketcan"));
            SocketCanConfig s;
            t.read("interface", s.interface);
            t.read("subject", s.subject, 1, UINT32_MAX);
            if (s.interface.empty() || s.interface.size() >= 16) {
                t.fail("interface", t.take("interface"), "must name a network interface (1..15 chars)");
            }
            t.finish();
            c.socketcan.push_back(std::move(s));
        }
    }
}

void read_pipeline(TableReader& r, DaemonConfig& c) {
    r.read("workers", c.workers, 0, 256);
    r.read("ring_capacity", c.ring_capacity, 16, 1 << 20);
    if ((c.ring_capacity & (c.ring_capacity - 1)) != 0) {
        r.fail("ring_capacity", r.take("ring_capacity"), "must be a power of two");
    }
    r.read("max_subjects", c.max_subjects, 1, 4096);
    r.read("assembly_deadline_ms", c.assembly_deadline_ms, 0.1, 10000.0);
}

std::string scalar_to_string(const toml::node& n) {
    if (n.is_integer()) return std::to_string(n.value<std::int64_t>().value());
    if (n.is_floating_point()) {
        std::ostringstream s;
        s.precision(17);
        s << n.as_floating_point()->get();
        return s.str();
    }
    if (n.is_boolean()) return n.value<bool>().value() ? "true" : "false";
    if (n.is_string()) return n.value<std::string>().value();
    return {};
}

void read_filter(TableReader& r, DaemonConfig& c) {
    r.read("name", c.filter_name);
    if (const auto* p = r.sub_table("params")) {
        for (const auto& [k, v] : *p) {
            if (!(v.is_number() || v.is_boolean() || v.is_string())) {
                throw ConfigError{"filter.params." + std::string(k.str()), line_of(v),
                                  "expected a number, boolean or string"};
            }
            c.filter_params.emplace_back(std::string(k.str()), scalar_to_string(v));
        }
    }
}

void read_vec3(TableReader& t, std::string_view key, std::array<double, 3>& out, double limit) {
    if (const auto* arr = t.array(key)) {
        if (arr->size() != 3) t.fail(key, arr, "expected [x, y, z]");
        for (std::size_t i = 0; i < 3; ++i) {
            const auto* e = arr->get(i);
            if (!e->is_number()) t.fail(key, e, "expected numbers");
            out[i] = number_of(*e);
            if (!std::isfinite(out[i]) || std::abs(out[i]) > limit) {
                std::ostringstream m;
                m << "components must be within +-" << limit;
                t.fail(key, e, m.str());
            }
        }
    }
}

void read_segment(TableReader& t, SegmentConfig& s) {
    t.read("name", s.name);
    if (s.name.empty()) t.fail("name", t.take("name"), "every segment needs a non-empty name");
    t.read("parent", s.parent);
    read_vec3(t, "offset_m", s.offset_m, 10.0);
    read_vec3(t, "end_m", s.end_m, 10.0);
    t.read("node", s.node, 1, 63);
    if (s.node == 0) t.fail("node", t.take("node"), "every segment needs a CAN node id (1..63)");
    t.read("filter", s.filter);
    t.finish();
}

void read_choice(TableReader& r, std::string_view key, bool& out, const char* yes, const char* no) {
    std::string v;
    r.read(key, v);
    if (v.empty()) return;
    if (v == yes) {
        out = true;
    } else if (v == no) {
        out = false;
    } else {
        r.fail(key, r.take(key), std::string("must be \"") + yes + "\" or \"" + no + "\"");
    }
}

void read_fusion(TableReader& r, DaemonConfig& c) {
    r.read("heading", c.fusion_heading);
    // The names of fusion::parse_heading_mode (the config library does not link the fusion
    // layer; pipeline_config.cpp converts, and a test checks both accept the same names).
    if (c.fusion_heading != "magnetometer" && c.fusion_heading != "joints" && c.fusion_heading != "auto") {
        r.fail("heading", r.take("heading"), "must be \"magnetometer\", \"joints\" or \"auto\"");
    }
    read_choice(r, "axis", c.fusion_estimate_axes, "estimate", "model");
}

void read_skeleton(TableReader& r, DaemonConfig& c) {
    r.read("calibration_dir", c.calibration_dir);
    r.read("calibration_s", c.calibration_s, 0.1, 60.0);
    r.read("auto_calibrate", c.auto_calibrate);
    if (c.auto_calibrate != "t-pose" && c.auto_calibrate != "n-pose" && c.auto_calibrate != "off") {
        r.fail("auto_calibrate", r.take("auto_calibrate"), "must be \"t-pose\", \"n-pose\" or \"off\"");
    }
    read_choice(r, "heading", c.heading_align, "align", "earth");
    read_choice(r, "facing", c.facing_from_sensor, "sensor", "given");
    r.read("facing_heading_deg", c.facing_heading_deg, -360.0, 360.0);
    read_vec3(r, "facing_sensor_axis", c.facing_sensor_axis, 1.0);
    {
        const auto& a = c.facing_sensor_axis;
        if (a[0] * a[0] + a[1] * a[1] + a[2] * a[2] < 0.25) {
            r.fail("facing_sensor_axis", r.take("facing_sensor_axis"), "must be a unit vector");
        }
    }
    r.read("smoothing_alpha", c.smoothing_alpha, 0.001, 1.0);
    r.read("root_height_m", c.root_height_m, 0.0, 5.0);
    if (const auto* arr = r.array("segment")) {
        std::set<std::string> names;
        std::set<int> nodes;
        for (const auto& item : *arr) {
            if (!item.is_table()) r.fail("segment", &item, "expected [[skeleton.segment]] tables");
            TableReader t(*item.as_table(), r.key_path("segment"));
            SegmentConfig s;
            read_segment(t, s);
            if (!names.insert(s.name).second) t.fail("name", t.take("name"), "duplicate segment name");
            if (!nodes.insert(s.node).second) t.fail("node", t.take("node"), "node id used twice");
            if (!s.parent.empty() && !names.count(s.parent)) {
                t.fail("parent", t.take("parent"), "parent must be a segment listed earlier");
            }
            if (s.parent.empty() && !c.segments.empty()) {
                t.fail("parent", t.take("parent"), "only the first segment may be the root");
            }
            c.segments.push_back(std::move(s));
        }
        if (c.segments.size() > 32) r.fail("segment", arr, "at most 32 segments");
    }
}

void read_serve(TableReader& r, DaemonConfig& c) {
    r.read("pose_listen", c.pose_listen);
    r.read("max_clients", c.max_clients, 1, 100000);
    r.read("threads", c.serve_threads, 1, 64);
    r.read("client_queue_frames", c.client_queue_frames, 1, 65536);
    r.read("handshake_timeout_s", c.handshake_timeout_s, 0.05, 3600.0);
    r.read("max_message_bytes", c.max_message_bytes, 64, 16 << 20);
    r.read("max_client_messages_per_s", c.max_client_messages_per_s, 0.1, 100000.0);
    r.read("client_message_burst", c.client_message_burst, 1, 100000);
    r.read("max_address_messages_per_s", c.max_address_messages_per_s, 0.1, 1e6);
    r.read("address_message_burst", c.address_message_burst, 1, 10000000);
    r.read("max_subscribe_subjects", c.max_subscribe_subjects, 1, 65536);
}

void read_control(TableReader& r, DaemonConfig& c) {
    r.read("token", c.control_token);
    // A token pasted with a stray space or newline, or made of blanks only, would either never
    // match what a client sends or look set while being trivially guessable: refuse both.
    const std::string& t = c.control_token;
    if (!t.empty()) {
        const bool blank_edge = std::isspace(static_cast<unsigned char>(t.front())) != 0 ||
                                std::isspace(static_cast<unsigned char>(t.back())) != 0;
        const bool control_char =
            std::any_of(t.begin(), t.end(), [](char ch) { return std::iscntrl(static_cast<unsigned char>(ch)) != 0; });
        if (blank_edge || control_char) {
            r.fail("token", r.take("token"),
                   "must not be blank, start or end with whitespace, or contain control characters "
                   "(\"\" disables control)");
        }
        // Failed attempts are rate-limited (docs/security.md, "Guessing the token"); the
        // length is what makes that limit enough.
        if (!blank_edge && !control_char && t.size() < kMinControlTokenLength) {
            r.fail("token", r.take("token"),
                   "must be at least " + std::to_string(kMinControlTokenLength) +
                       " characters (e.g. `openssl rand -hex 16`; \"\" disables control)");
        }
    }
    if (const auto* n = r.take("loopback_only")) {
        if (!n->is_boolean()) r.fail("loopback_only", n, "expected true or false");
        c.control_loopback_only = n->value<bool>().value();
    }
}

void read_outputs(TableReader& r, DaemonConfig& c) {
    r.read("bvh_listen", c.bvh_listen);
    if (const auto* n = r.take("bvh_live")) {
        if (!n->is_boolean()) r.fail("bvh_live", n, "expected true or false");
        c.bvh_live = n->value<bool>().value();
    }
    r.read("bvh_max_clients", c.bvh_max_clients, 1, 10000);
    r.read("bvh_threads", c.bvh_threads, 1, 64);
    r.read("bvh_subject", c.bvh_subject, 0, UINT32_MAX);
    if (const auto* n = r.take("bvh_unit")) {
        const auto unit = n->value<std::string>();
        if (unit == "cm")
            c.bvh_units_per_m = 100.0;
        else if (unit == "m")
            c.bvh_units_per_m = 1.0;
        else if (unit == "mm")
            c.bvh_units_per_m = 1000.0;
        else
            r.fail("bvh_unit", n, "must be \"cm\", \"m\" or \"mm\"");
    }
    r.read("bvh_rotation_order", c.bvh_rotation_order);
    {
        const std::string& o = c.bvh_rotation_order;
        const bool ok = o.size() == 3 && o.find_first_not_of("XYZ") == std::string::npos && o[0] != o[1] &&
                        o[1] != o[2] && o[0] != o[2];
        if (!ok)
            r.fail("bvh_rotation_order", r.take("bvh_rotation_order"),
                   "must be three distinct letters of XYZ, e.g. \"ZXY\"");
    }
    r.read("bvh_frame_time_s", c.bvh_frame_time_s, 0.0, 10.0);
    r.read("record_dir", c.record_dir);
    r.read("record_flush_interval_s", c.record_flush_interval_s, 0.01, 60.0);
    if (const auto* n = r.take("raw_record")) {
        if (!n->is_boolean()) r.fail("raw_record", n, "expected true or false");
        c.raw_record = n->value<bool>().value();
    }
    r.read_zero_or("raw_rotate_mb", c.raw_rotate_mb, 1.0, 1e6);
    r.read_zero_or("raw_rotate_s", c.raw_rotate_s, 10.0, 1e7);
    r.read("raw_ring_capacity", c.raw_ring_capacity, 16, 1 << 24);
    if ((c.raw_ring_capacity & (c.raw_ring_capacity - 1)) != 0) {
        r.fail("raw_ring_capacity", r.take("raw_ring_capacity"), "must be a power of two");
    }
    r.read("export_memory_mb", c.export_memory_mb, 1, 65536);
    r.read("export_memory_per_address_mb", c.export_memory_per_address_mb, 1, 65536);
    r.read("offline_export_max_mb", c.offline_export_max_mb, 1, 65536);
    r.read_zero_or("take_start_min_free_mb", c.take_start_min_free_mb, 0.01, 1e6);
}

void read_http(TableReader& r, DaemonConfig& c) {
    if (const auto* n = r.take("enabled")) {
        if (!n->is_boolean()) r.fail("enabled", n, "expected true or false");
        c.http_enabled = n->value<bool>().value();
    }
    r.read("listen", c.http_listen);
    r.read("max_clients", c.http_max_clients, 1, 10000);
    r.read("threads", c.http_threads, 1, 64);
    r.read("ws_queue_frames", c.http_ws_queue_frames, 1, 4096);
    if (const auto* arr = r.array("allowed_origins")) {
        for (const auto& item : *arr) {
            const auto origin = item.value<std::string>();
            if (!origin || origin->empty())
                r.fail("allowed_origins", &item, "expected origin strings like \"https://host:port\"");
            c.http_allowed_origins.push_back(*origin);
        }
    }
    if (const auto* arr = r.array("allowed_hosts")) {
        for (const auto& item : *arr) {
            const auto name = item.value<std::string>();
            const bool valid = name && !name->empty() && name->size() <= 253 &&
                               std::all_of(name->begin(), name->end(), [](unsigned char ch) {
                                   return std::isalnum(ch) != 0 || ch == '-' || ch == '.' || ch == '_';
                               });
            if (!valid) r.fail("allowed_hosts", &item, "expected host names like \"mocap.lab\" (no scheme, no port)");
            c.http_allowed_hosts.push_back(*name);
        }
    }
}

void read_limits(TableReader& r, DaemonConfig& c) {
    r.read("sink_per_address", c.sink_per_address, 0, 100000);
    r.read("pose_per_address", c.pose_per_address, 0, 100000);
    r.read("bvh_per_address", c.bvh_per_address, 0, 100000);
    r.read("http_per_address", c.http_per_address, 0, 100000);
    if (const auto* n = r.take("loopback")) {
        if (!n->is_boolean()) r.fail("loopback", n, "expected true or false");
        c.limits_on_loopback = n->value<bool>().value();
    }
    r.read("stall_evict_s", c.stall_evict_s, 0.1, 3600.0);
}

void read_bool(TableReader& r, std::string_view key, bool& out) {
    if (const auto* n = r.take(key)) {
        if (!n->is_boolean()) r.fail(key, n, "expected true or false");
        out = n->value<bool>().value();
    }
}

// A NATS subject token: non-empty, no '.', no wildcard ('*', '>') and no whitespace or
// control character, so "mocap.<site>.<subject>.pose" always has exactly four tokens.
bool is_subject_token(const std::string& t) {
    return !t.empty() && std::none_of(t.begin(), t.end(), [](char ch) {
        const auto u = static_cast<unsigned char>(ch);
        return ch == '.' || ch == '*' || ch == '>' || std::isspace(u) != 0 || std::iscntrl(u) != 0;
    });
}

void read_cluster(TableReader& r, DaemonConfig& c) {
    r.read("nats_url", c.cluster_nats_url);
    r.read("site", c.cluster_site);
    if (!is_subject_token(c.cluster_site)) {
        r.fail("site", r.take("site"), "must be one NATS subject token: not empty, no '.', '*', '>' or whitespace");
    }
    r.read("host_id", c.cluster_host_id);
    if (!c.cluster_host_id.empty() && !is_subject_token(c.cluster_host_id)) {
        r.fail("host_id", r.take("host_id"),
               "must be \"\" (the host name) or one NATS subject token: no '.', '*', '>' or whitespace");
    }
    r.read("user", c.cluster_user);
    r.read("password", c.cluster_password);
    r.read("creds_file", c.cluster_creds_file);
    r.read("nkey_seed_file", c.cluster_nkey_seed_file);
    read_bool(r, "allow_anonymous", c.cluster_allow_anonymous);
    r.read("calibration_key_file", c.cluster_calibration_key_file);
    r.read("tls_ca_file", c.cluster_tls_ca_file);
    r.read("tls_cert_file", c.cluster_tls_cert_file);
    r.read("tls_key_file", c.cluster_tls_key_file);
    r.read("raw_replicas", c.cluster_raw_replicas, 1, 5);
    r.read("queue_frames", c.cluster_queue_frames, 1, 1 << 20);
    r.read("raw_queue_samples", c.cluster_raw_queue_samples, 1, 1 << 24);
}

void read_vmc(TableReader& r, DaemonConfig& c) {
    read_bool(r, "enabled", c.vmc_enabled);
    if (const auto* arr = r.array("destinations")) {
        c.vmc_destinations.clear();
        for (const auto& item : *arr) {
            const auto text = item.value<std::string>();
            std::string err;
            if (!text) r.fail("destinations", &item, "expected \"host:port\" strings");
            if (!parse_destination(*text, &err)) r.fail("destinations", &item, "\"" + *text + "\": " + err);
            c.vmc_destinations.push_back(*text);
        }
        if (c.vmc_destinations.empty() || c.vmc_destinations.size() > 16) {
            r.fail("destinations", arr, "list 1..16 receivers as \"host:port\"");
        }
    }
    r.read("subject", c.vmc_subject, 0, UINT32_MAX);
    if (const auto* bones = r.sub_table("bones")) {
        for (const auto& [k, v] : *bones) {
            if (!v.is_string()) {
                throw ConfigError{"vmc.bones." + std::string(k.str()), line_of(v),
                                  "expected a Unity HumanBodyBones name such as \"Hips\""};
            }
            c.vmc_bones.emplace_back(std::string(k.str()), v.value<std::string>().value());
        }
    }
}

// True when the text holds something other than blanks and comment lines: an empty config
// file is far more likely a truncated or mistyped one than a request for every default
// (which would bind every interface).
bool has_settings(std::string_view text) {
    std::istringstream in{std::string(text)};
    for (std::string line; std::getline(in, line);) {
        const auto first = line.find_first_not_of(" \t\r\f\v");
        if (first != std::string::npos && line[first] != '#') return true;
    }
    return false;
}

}  // namespace

std::string cluster_host_id(const DaemonConfig& config) {
    if (!config.cluster_host_id.empty()) return config.cluster_host_id;
    std::array<char, 256> name{};
    if (::gethostname(name.data(), name.size() - 1) != 0) return {};
    std::string id(name.data());
    if (const auto dot = id.find('.'); dot != std::string::npos) id.resize(dot);
    for (char& ch : id) {
        if (!is_subject_token(std::string(1, ch))) ch = '_';
    }
    return id;
}

std::optional<DaemonConfig> parse_config(std::string_view toml_text, std::string_view source_name, std::string* error) {
    DaemonConfig c;
    try {
        const toml::table root = toml::parse(toml_text, source_name);
        TableReader top(root, "");
        using Section = void (*)(TableReader&, DaemonConfig&);
        const std::pair<const char*, Section> sections[] = {
            {"log", read_log},       {"ingest", read_ingest},   {"pipeline", read_pipeline},
            {"filter", read_filter}, {"fusion", read_fusion},   {"skeleton", read_skeleton},
            {"serve", read_serve},   {"control", read_control}, {"outputs", read_outputs},
            {"http", read_http},     {"limits", read_limits},   {"cluster", read_cluster},
            {"vmc", read_vmc},
        };
        for (const auto& [name, fn] : sections) {
            if (const auto* t = top.sub_table(name)) {
                TableReader r(*t, name);
                fn(r, c);
                r.finish();
            }
        }
        top.finish();
    } catch (const toml::parse_error& e) {
        *error = std::string(source_name) + ":" + std::to_string(e.source().begin.line) +
                 ": syntax: " + std::string(e.description());
        return std::nullopt;
    } catch (const ConfigError& e) {
        *error = std::string(source_name) + ":" + std::to_string(e.line) + ": " + e.key + ": " + e.message;
        return std::nullopt;
    }
    return c;
}

std::optional<DaemonConfig> load_config_file(const std::string& path, std::string* error) {
    // A directory opens fine with ifstream and reads as empty; a FIFO would block the open.
    // Both are refused before opening, by what stat says the path is.
    std::error_code ec;
    const auto st = std::filesystem::status(path, ec);
    if (ec) {
        *error = path + ": cannot open for reading: " + ec.message();
        return std::nullopt;
    }
    if (!std::filesystem::is_regular_file(st)) {
        *error = path + ": not a regular file" + (std::filesystem::is_directory(st) ? " (a directory)" : "") +
                 "; --config takes a TOML file";
        return std::nullopt;
    }
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        *error = path + ": cannot open for reading";
        return std::nullopt;
    }
    std::ostringstream s;
    s << in.rdbuf();
    if (!has_settings(s.str())) {
        *error = path +
                 ": the file has no settings (empty or comments only); mocapd --print-default-config "
                 "writes a complete one";
        return std::nullopt;
    }
    return parse_config(s.str(), path, error);
}

}  // namespace mocap::daemon
