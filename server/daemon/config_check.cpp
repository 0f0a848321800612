#include "daemon/config_check.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <set>
#include <utility>
#include <vector>

#include "cluster/calibration_trust.hpp"
#include "daemon/pipeline_config.hpp"
#include "filter/filter_factory.hpp"
#include "serve/vmc_rig.hpp"
#include "serve/vmc_sender.hpp"

namespace mocap::daemon {
namespace {

// The filter `name`, as `key` names it, built with [filter.params]: the pipeline builds every
// segment's filter with the same parameter list, so a parameter that only the default filter
// knows fails for a segment that overrides the filter, at start-up; it fails here instead.
bool check_filter(const std::string& key, const std::string& name, const filter::FilterParamList& params,
                  std::string* error) {
    const auto names = filter::filter_names();
    if (std::find(names.begin(), names.end(), name) == names.end()) {
        std::string list;
        for (std::string_view n : names)
            list += (list.empty() ? "" : ", ") + std::string(n);
        *error = key + ": unknown filter \"" + name + "\" (known: " + list + ")";
        return false;
    }
    std::string err;
    if (filter::make_filter(name, params, &err)) return true;
    // Name the offending key: the first parameter that fails on its own (a failure of the
    // combination only, e.g. a check across two keys, names the table).
    for (const auto& kv : params) {
        std::string one;
        if (!filter::make_filter(name, {kv}, &one)) {
            *error = "filter.params." + kv.first + ": " + one + (key == "filter.name" ? "" : " (used by " + key + ")");
            return false;
        }
    }
    *error = "filter.params: " + err;
    return false;
}

bool is_unspecified(const std::string& host) {
    return host == "0.0.0.0" || host == "::" || host == "0:0:0:0:0:0:0:0";
}

// Two listeners collide when they share a port and an address, or one of them binds every
// address (0.0.0.0 or ::) on that port.
bool check_listeners(const DaemonConfig& c, std::string* error) {
    std::vector<std::pair<const char*, const Endpoint*>> listeners{{"ingest.sink_listen", &c.sink_listen},
                                                                   {"serve.pose_listen", &c.pose_listen}};
    if (c.bvh_live) listeners.emplace_back("outputs.bvh_listen", &c.bvh_listen);
    if (c.http_enabled) listeners.emplace_back("http.listen", &c.http_listen);
    for (std::size_t i = 0; i < listeners.size(); ++i) {
        for (std::size_t j = 0; j < i; ++j) {
            const Endpoint& a = *listeners[j].second;
            const Endpoint& b = *listeners[i].second;
            if (a.port != b.port) continue;
            if (a.host == b.host || is_unspecified(a.host) || is_unspecified(b.host)) {
                *error = std::string(listeners[i].first) + ": " + b.str() + " collides with " + listeners[j].first +
                         " (" + a.str() + "): each listener needs its own port";
                return false;
            }
        }
    }
    return true;
}

// A port's serve threads each take every published frame (encoded once, shared) and wake
// for it, so a thread that can never hold a client costs CPU for nothing: refuse more
// threads than client slots on the ports whose thread count is their own key.
bool check_serve_threads(const DaemonConfig& c, std::string* error) {
    const auto check = [error](const char* key, std::uint32_t threads, const char* slots_key, std::uint32_t slots) {
        if (threads <= slots) return true;
        *error = std::string(key) + ": " + std::to_string(threads) + " threads for " + std::to_string(slots) +
                 " connection slots (" + slots_key + "): at most one thread per slot";
        return false;
    };
    if (c.bvh_live && !check("outputs.bvh_threads", c.bvh_threads, "outputs.bvh_max_clients", c.bvh_max_clients)) {
        return false;
    }
    return !c.http_enabled || check("http.threads", c.http_threads, "http.max_clients", c.http_max_clients);
}

bool readable_file(const std::string& path) {
    struct stat st {};
    return ::stat(path.c_str(), &st) == 0 && S_ISREG(st.st_mode) && ::access(path.c_str(), R_OK) == 0;
}

// [cluster]: only with nats_url set. A publisher without credentials would connect to any
// server that accepts anonymous clients, which an operator must ask for explicitly; the files
// it names are read at connect time, so a missing one is refused here, not at the first
// reconnect.
bool check_cluster(const DaemonConfig& c, std::string* error) {
    if (c.cluster_nats_url.empty()) return true;
    const bool user = !c.cluster_user.empty() || !c.cluster_password.empty();
    if (user && (c.cluster_user.empty() || c.cluster_password.empty())) {
        *error = "cluster.user: user and password go together (both set or both empty)";
        return false;
    }
    const int methods =
        (user ? 1 : 0) + (c.cluster_creds_file.empty() ? 0 : 1) + (c.cluster_nkey_seed_file.empty() ? 0 : 1);
    if (methods == 0 && !c.cluster_allow_anonymous) {
        *error =
            "cluster.nats_url: set credentials (user + password, creds_file or nkey_seed_file), or "
            "allow_anonymous = true to connect without any";
        return false;
    }
    if (methods > 1) {
        *error = "cluster: give one kind of credentials: user + password, creds_file or nkey_seed_file";
        return false;
    }
    if ((c.cluster_tls_cert_file.empty()) != (c.cluster_tls_key_file.empty())) {
        *error = "cluster.tls_cert_file: tls_cert_file and tls_key_file go together";
        return false;
    }
    const std::pair<const char*, const std::string*> files[] = {{"cluster.creds_file", &c.cluster_creds_file},
                                                                {"cluster.nkey_seed_file", &c.cluster_nkey_seed_file},
                                                                {"cluster.tls_ca_file", &c.cluster_tls_ca_file},
                                                                {"cluster.tls_cert_file", &c.cluster_tls_cert_file},
                                                                {"cluster.tls_key_file", &c.cluster_tls_key_file}};
    for (const auto& [key, path] : files) {
        if (!path->empty() && !readable_file(*path)) {
            *error = std::string(key) + ": \"" + *path + "\" is not a readable file";
            return false;
        }
    }
    if (!c.cluster_calibration_key_file.empty()) {
        std::string why;
        if (!cluster::read_calibration_key(c.cluster_calibration_key_file, &why)) {
            *error = "cluster.calibration_key_file: " + why;
            return false;
        }
    }
    if (cluster_host_id(c).empty()) {
        *error = "cluster.host_id: the host name gives no usable id; set host_id";
        return false;
    }
    return true;
}

// A SocketCAN bus keeps its own subject id: one inside the sinks' range (subject_id_base +
// 1..max_subjects) or another bus's id would feed two buses into one subject.
bool check_subject_ids(const DaemonConfig& c, std::string* error) {
    const std::uint64_t first = std::uint64_t{c.subject_id_base} + 1;
    const std::uint64_t last = std::uint64_t{c.subject_id_base} + c.max_subjects;
    for (std::size_t i = 0; i < c.socketcan.size(); ++i) {
        const std::uint32_t id = c.socketcan[i].subject;
        const std::string key = "ingest.socketcan[" + std::to_string(i) + "].subject: " + std::to_string(id);
        if (id >= first && id <= last) {
            *error = key + " is a sink's subject id (ingest.subject_id_base + 1..pipeline.max_subjects = " +
                     std::to_string(first) + ".." + std::to_string(last) + "); give the bus an id outside that range";
            return false;
        }
        for (std::size_t j = 0; j < i; ++j) {
            if (c.socketcan[j].subject == id) {
                *error = key + " is also ingest.socketcan[" + std::to_string(j) + "]'s subject";
                return false;
            }
        }
    }
    return true;
}

// A subject key (0 = the first subject with a frame) must name a subject this config serves.
bool check_subject(const DaemonConfig& c, const char* key, std::uint32_t id, std::string* error) {
    if (id == 0) return true;
    const auto ids = subject_ids_from_config(c);
    if (std::find(ids.begin(), ids.end(), id) != ids.end()) return true;
    *error = std::string(key) + ": " + std::to_string(id) +
             " is not a configured subject (0 = the first subject with a frame, or ingest.subject_id_base + "
             "1..pipeline.max_subjects = " +
             std::to_string(static_cast<std::uint64_t>(c.subject_id_base) + 1) + ".." +
             std::to_string(static_cast<std::uint64_t>(c.subject_id_base) + c.max_subjects) +
             ", or an ingest.socketcan subject)";
    return false;
}

// [vmc]: the segment -> humanoid bone mapping against the body model (also while the output
// is off, when a mapping is written); with the output on every destination must parse, and
// with kResolve (--check-config) resolve: a typo in a host name is named there.
bool check_vmc(const DaemonConfig& c, HostLookups lookups, std::string* error) {
    if (!c.vmc_enabled && c.vmc_bones.empty()) return true;
    std::string err;
    const auto model = body_model_from_config(c, &err);
    if (!model) {
        *error = err;
        return false;
    }
    if (!serve::VmcRig::build(*model, c.vmc_bones, &err)) {
        *error = err;
        return false;
    }
    if (!c.vmc_enabled) return true;
    for (std::size_t i = 0; i < c.vmc_destinations.size(); ++i) {
        const auto ep = parse_destination(c.vmc_destinations[i], &err);
        if (ep && (lookups == HostLookups::kSkip || serve::resolve_udp({ep->host, ep->port}, &err))) continue;
        *error = "vmc.destinations[" + std::to_string(i) + "]: ";
        if (!ep) *error += "\"" + c.vmc_destinations[i] + "\": ";
        *error += err;
        return false;
    }
    return true;
}

bool check_config_impl(const DaemonConfig& c, HostLookups lookups, std::string* error) {
    std::string err;
    if (!check_filter("filter.name", c.filter_name, c.filter_params, error)) return false;
    for (std::size_t i = 0; i < c.segments.size(); ++i) {
        const auto& s = c.segments[i];
        if (s.filter.empty() || s.filter == c.filter_name) continue;
        const std::string key = "skeleton.segment[" + std::to_string(i) + "].filter";
        if (!check_filter(key, s.filter, c.filter_params, error)) return false;
    }
    if (!body_model_from_config(c, &err)) {
        *error = err;
        return false;
    }
    if (!check_subject_ids(c, error)) return false;
    if (!check_subject(c, "outputs.bvh_subject", c.bvh_subject, error)) return false;
    if (!check_subject(c, "vmc.subject", c.vmc_subject, error)) return false;
    if (!check_vmc(c, lookups, error)) return false;
    if (!check_listeners(c, error)) return false;
    if (!check_serve_threads(c, error)) return false;
    if (!check_cluster(c, error)) return false;
    if (c.raw_record) {
        struct stat st {};
        if (::stat(c.record_dir.c_str(), &st) != 0 || !S_ISDIR(st.st_mode)) {
            *error =
                "outputs.record_dir: \"" + c.record_dir + "\" is not a directory (raw_record = true records there)";
            return false;
        }
        if (::access(c.record_dir.c_str(), W_OK | X_OK) != 0) {
            *error = "outputs.record_dir: \"" + c.record_dir + "\" is not writable (raw_record = true records there)";
            return false;
        }
    }
    return true;
}

}  // namespace

bool check_config(const DaemonConfig& config, std::string_view source_name, std::string* error, HostLookups lookups) {
    std::string err;
    if (check_config_impl(config, lookups, &err)) return true;
    *error = std::string(source_name) + ": " + err;
    return false;
}

std::optional<DaemonConfig> load_checked_config(const std::string& path, std::string* error, HostLookups lookups) {
    constexpr std::string_view kEmbedded = "<embedded mocapd.toml>";
    auto c = path.empty() ? parse_config(embedded_default_config(), kEmbedded, error) : load_config_file(path, error);
    if (c && !check_config(*c, path.empty() ? kEmbedded : std::string_view(path), error, lookups)) c.reset();
    return c;
}

}  // namespace mocap::daemon
