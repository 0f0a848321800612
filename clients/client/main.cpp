// mocap-client — command-line client of mocapd's pose service.
//
//   mocap-client --connect HOST:PORT cat [--frames N] [--json] [--subject ID]...
//   mocap-client --nats URL [--site S] cat|load|record ... (the same, from a NATS cluster)
//   mocap-client --connect HOST:PORT stats [--json]
//   mocap-client --connect HOST:PORT control --token T calibrate --subject ID [--pose T|N]
//   mocap-client --connect HOST:PORT control --token T record-start [--path FILE]
//   mocap-client --connect HOST:PORT control --token T record-start --take [--name N] [--notes TEXT]
//   mocap-client --connect HOST:PORT control --token T record-stop [--take] | reload
//   mocap-client [--http HOST:PORT] takes list|download|start|stop|delete ... (take_commands.hpp)
//   mocap-client --connect HOST:PORT load --clients N --duration S [--protocol pose|bvh|ws] [--json]
//   mocap-client --connect HOST:7002 record --out FILE.bvh --frames N [--subject ID]
//   mocap-client --connect HOST:PORT angles --out FILE.csv --frames N [--subject ID]
//
// Exit codes: 0 success, 1 refused/failed request or bad data, 2 connection problem.
// The token may also come from the environment (MOCAP_TOKEN) to keep it out of `ps`, and the
// NATS password likewise (MOCAP_NATS_PASSWORD).
#include <CLI/CLI.hpp>

#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>

#include "core/guarded_main.hpp"
#include "load_client.hpp"
#include "nats_load_client.hpp"
#include "nats_pose_client.hpp"
#include "output_commands.hpp"
#include "pose_client.hpp"
#include "take_commands.hpp"

namespace {

using namespace std::chrono_literals;
using mocap::client::PoseClient;
using mocap::client::ReadStatus;
namespace v1 = mocap::v1;

constexpr int kExitFailed = 1;
constexpr int kExitConnection = 2;

std::uint32_t parse_fields(const std::vector<std::string>& names) {
    std::uint32_t fields = 0;
    for (const std::string& n : names) {
        if (n == "orientations") fields |= v1::FIELD_ORIENTATIONS;
        if (n == "positions") fields |= v1::FIELD_POSITIONS;
        if (n == "joints") fields |= v1::FIELD_JOINT_ANGLES;
        if (n == "raw") fields |= v1::FIELD_RAW;
        if (n == "all") fields |= 0xF;
    }
    return fields;
}

// The wire carries floats: a float-valued JSON prints each as the shortest text that reads
// back to the same float ("0.70710677"), not the 17 digits of its double widening.
using FloatJson =
    nlohmann::basic_json<nlohmann::ordered_map, std::vector, std::string, bool, std::int64_t, std::uint64_t, float>;

// Names and error texts come from the peer: invalid UTF-8 becomes U+FFFD, not an exception.
template <class Json>
std::string dump_json(const Json& j) {
    return j.dump(-1, ' ', false, Json::error_handler_t::replace);
}

std::string frame_json(const v1::SkeletonFrame& f, const v1::Hello& hello, std::int64_t receive_us) {
    FloatJson out{{"subject", f.subject_id()},
                  {"sync", f.sync()},
                  {"sample_us", f.sample_us()},
                  {"receive_us", receive_us},
                  {"times",
                   {{"sink_send_us", f.times().sink_send_us()},
                    {"received_us", f.times().received_us()},
                    {"filtered_us", f.times().filtered_us()},
                    {"assembled_us", f.times().assembled_us()},
                    {"encoded_us", f.times().encoded_us()}}}};
    const int n = static_cast<int>(f.segment_count());
    const bool has_q = f.q_world_segment_wxyz_size() == 4 * n;
    const bool has_p = f.position_m_size() == 3 * n;
    const bool has_raw = f.q_earth_sensor_wxyz_size() == 4 * n;
    auto array = [](const auto& values, int first, int count) {
        FloatJson a = FloatJson::array();
        for (int c = 0; c < count; ++c)
            a.push_back(values.Get(first + c));
        return a;
    };
    FloatJson& segments = out["segments"] = FloatJson::array();
    const auto& segs = hello.skeleton().segments();
    for (int i = 0; i < n; ++i) {
        FloatJson s{{"name", i < segs.size() ? segs.Get(i).name() : "segment" + std::to_string(i)}};
        if (has_q) s["q"] = array(f.q_world_segment_wxyz(), 4 * i, 4);
        if (has_p) s["p"] = array(f.position_m(), 3 * i, 3);
        if (has_raw) s["q_raw"] = array(f.q_earth_sensor_wxyz(), 4 * i, 4);
        s["flags"] = i < f.flags_size() ? f.flags(i) : 0u;
        segments.push_back(std::move(s));
    }
    if (f.joint_angles_rad_size() > 0) {
        FloatJson& angles = out["joint_angles_rad"] = FloatJson::object();
        const auto& names = hello.skeleton().joint_angle_names();
        for (int j = 0; j < f.joint_angles_rad_size(); ++j) {
            angles[j < names.size() ? names.Get(j) : "joint" + std::to_string(j)] = f.joint_angles_rad(j);
        }
    }
    return dump_json(out);
}

std::string frame_text(const v1::SkeletonFrame& f, const v1::Hello& hello, std::int64_t receive_us) {
    int stale = 0, never = 0;
    for (std::uint32_t flags : f.flags()) {
        stale += (flags & v1::SEGMENT_STALE) ? 1 : 0;
        never += (flags & v1::SEGMENT_NEVER_SEEN) ? 1 : 0;
    }
    char head[256];
    const double latency_ms = f.times().sink_send_us() ? (receive_us - f.times().sink_send_us()) / 1000.0 : 0.0;
    std::snprintf(head, sizeof head, "subject %u sync %llu t=%.3fs latency=%.2fms segments=%u stale=%d never=%d",
                  f.subject_id(), static_cast<unsigned long long>(f.sync()), f.sample_us() / 1e6, latency_ms,
                  f.segment_count(), stale, never);
    std::string line = head;
    if (f.segment_count() > 0 && f.q_world_segment_wxyz_size() >= 4) {
        const std::string root =
            hello.skeleton().segments_size() > 0 ? hello.skeleton().segments(0).name() : "segment0";
        char seg[160];
        std::snprintf(seg, sizeof seg, " | %s q=(%.3f %.3f %.3f %.3f)", root.c_str(), f.q_world_segment_wxyz(0),
                      f.q_world_segment_wxyz(1), f.q_world_segment_wxyz(2), f.q_world_segment_wxyz(3));
        line += seg;
        if (f.position_m_size() >= 3) {
            std::snprintf(seg, sizeof seg, " p=(%.3f %.3f %.3f)", f.position_m(0), f.position_m(1), f.position_m(2));
            line += seg;
        }
    }
    return line;
}

// `Client` is PoseClient (the pose service) or NatsPoseClient (the cluster): same output.
template <class Client>
int run_cat(Client& client, const mocap::client::SubscribeOptions& sub, std::uint64_t frames, bool json,
            double idle_timeout_s) {
    std::string error;
    if (!client.subscribe(sub, 3s, error)) {
        std::cerr << "mocap-client: " << error << "\n";
        return kExitConnection;
    }
    const auto idle = std::chrono::milliseconds(static_cast<long long>(idle_timeout_s * 1000));
    v1::SkeletonFrame f;
    std::uint64_t shown = 0, drops_reported = 0;
    while (frames == 0 || shown < frames) {
        const ReadStatus s = client.next_frame(f, idle);
        if (client.drops_announced() != drops_reported) {
            std::cerr << "mocap-client: server dropped " << client.drops_announced() - drops_reported
                      << " frame(s) for this client (reading too slowly)\n";
            drops_reported = client.drops_announced();
        }
        if (s == ReadStatus::kTimeout) {
            std::cerr << "mocap-client: no frame within " << idle_timeout_s << " s\n";
            return kExitFailed;
        }
        if (s != ReadStatus::kMessage) {
            std::cerr << "mocap-client: connection ended"
                      << (client.goodbye() ? ": " + client.goodbye()->message() : std::string()) << "\n";
            return frames == 0 ? 0 : kExitConnection;
        }
        std::cout << (json ? frame_json(f, client.hello(), client.last_receive_us())
                           : frame_text(f, client.hello(), client.last_receive_us()))
                  << '\n';
        if (frames != 0 && (shown + 1) % 64 != 0) {
        } else {
            std::cout.flush();
        }
        ++shown;
    }
    std::cout.flush();
    return 0;
}

int run_stats(PoseClient& client, bool json) {
    std::string error;
    v1::Stats stats;
    if (!client.request_stats(stats, 3s, error)) {
        std::cerr << "mocap-client: " << error << "\n";
        return kExitConnection;
    }
    if (json) {
        nlohmann::ordered_json out{{"server_time_us", stats.server_time_us()}};
        nlohmann::ordered_json& counters = out["counters"] = nlohmann::ordered_json::object();
        for (const auto& c : stats.counters())
            counters[c.name()] = c.value();
        nlohmann::ordered_json& latencies = out["latencies"] = nlohmann::ordered_json::array();
        for (const auto& l : stats.latencies()) {
            latencies.push_back({{"stage", l.stage()},
                                 {"count", l.count()},
                                 {"p50_us", l.p50_us()},
                                 {"p90_us", l.p90_us()},
                                 {"p99_us", l.p99_us()},
                                 {"max_us", l.max_us()}});
        }
        std::cout << dump_json(out) << std::endl;
        return 0;
    }
    std::printf("%s\n", client.hello().server_version().c_str());
    for (const auto& c : stats.counters()) {
        std::printf("%-44s %llu\n", c.name().c_str(), static_cast<unsigned long long>(c.value()));
    }
    if (stats.latencies_size() > 0) {
        std::printf("\n%-16s %10s %10s %10s %10s %10s\n", "stage", "count", "p50_us", "p90_us", "p99_us", "max_us");
        for (const auto& l : stats.latencies()) {
            std::printf("%-16s %10llu %10.1f %10.1f %10.1f %10.1f\n", l.stage().c_str(),
                        static_cast<unsigned long long>(l.count()), l.p50_us(), l.p90_us(), l.p99_us(), l.max_us());
        }
    }
    return 0;
}

int run_control(PoseClient& client, const v1::ControlRequest& request) {
    std::string error;
    v1::ControlReply reply;
    if (!client.control(request, reply, 10s, error)) {
        std::cerr << "mocap-client: " << error << "\n";
        return kExitConnection;
    }
    if (!reply.ok()) {
        std::cerr << "mocap-client: refused: " << reply.error() << "\n";
        return kExitFailed;
    }
    std::cout << "ok" << (reply.take_name().empty() ? "" : " " + reply.take_name()) << "\n";
    return 0;
}

}  // namespace

// `load`'s report, for either transport; exit 0 when every client (and every stalled one) got in.
static int print_load(const mocap::client::LoadResult& r, const mocap::client::LoadOptions& options, bool json) {
    if (json) {
        std::cout << mocap::client::load_result_json(r) << std::endl;
    } else {
        std::printf("clients %zu (connected %zu, closed early %zu, stalled %zu), %.2f s\n", r.clients, r.connected,
                    r.closed_early, r.stalled, r.duration_s);
        std::printf("frames %llu (per client %llu..%llu), gaps %llu (missing %llu), drops %llu\n",
                    static_cast<unsigned long long>(r.frames), static_cast<unsigned long long>(r.frames_per_client_min),
                    static_cast<unsigned long long>(r.frames_per_client_max), static_cast<unsigned long long>(r.gaps),
                    static_cast<unsigned long long>(r.missing_frames), static_cast<unsigned long long>(r.drops));
        if (r.p50_ms) {
            // A BVH line has no timestamp: its figure is the spread over the clients.
            std::printf("latency %s: p50 %.3f ms, p90 %.3f ms, p99 %.3f ms, max %.3f ms\n",
                        options.protocol == "bvh" ? "first client's receive -> receive" : "sink-send -> receive",
                        *r.p50_ms, *r.p90_ms, *r.p99_ms, *r.max_ms);
        }
        if (!r.error.empty()) std::printf("first error: %s\n", r.error.c_str());
    }
    return r.connected == r.clients && r.stalled == options.stalled ? 0 : kExitConnection;
}

static int run(int argc, char** argv) {
    CLI::App app{"mocap-client: read poses from mocapd, query its stats, send control requests"};
    std::string connect = "127.0.0.1:7001";
    app.add_option("--connect", connect, "HOST:PORT of mocapd's pose service")->capture_default_str();
    double connect_timeout_s = 3.0;
    app.add_option("--connect-timeout", connect_timeout_s, "seconds to connect and get Hello")->capture_default_str();
    mocap::client::NatsOptions nats;
    app.add_option("--nats", nats.url,
                   "read poses from this NATS cluster instead (nats://HOST:PORT[,...]); cat, load and record");
    app.add_option("--site", nats.site, "the cluster's [cluster] site")->capture_default_str();
    app.add_option("--nats-user", nats.user, "NATS user (password: --nats-password or MOCAP_NATS_PASSWORD)");
    app.add_option("--nats-password", nats.password, "NATS password");
    app.add_option("--nats-creds", nats.creds_file, "NATS .creds file");
    app.require_subcommand(1);

    mocap::client::SubscribeOptions sub;
    std::vector<std::string> field_names;

    auto* cat = app.add_subcommand("cat", "print received poses, one line per frame");
    std::uint64_t cat_frames = 0;
    bool cat_json = false;
    double cat_idle_s = 10.0;
    cat->add_option("--frames", cat_frames, "stop after N frames (0 = until the server closes)");
    cat->add_flag("--json", cat_json, "one JSON object per frame per line");
    cat->add_option("--subject", sub.subject_ids, "subject id (repeatable; default all)");
    cat->add_option("--decimation", sub.decimation, "every n-th frame per subject")->capture_default_str();
    cat->add_option("--fields", field_names, "orientations, positions, joints, raw, all")->delimiter(',');
    cat->add_option("--timeout", cat_idle_s, "give up after this many seconds without a frame")->capture_default_str();

    auto* stats = app.add_subcommand("stats", "print the server's counters and stage latencies");
    bool stats_json = false;
    stats->add_flag("--json", stats_json, "one JSON object");

    auto* control = app.add_subcommand("control", "calibrate, start/stop recording, reload");
    std::string token;
    control->add_option("--token", token, "control token (or set MOCAP_TOKEN)");
    control->require_subcommand(1);
    auto* calibrate = control->add_subcommand("calibrate", "calibrate a subject from its still pose");
    std::uint32_t cal_subject = 0;
    std::string cal_pose = "T";
    calibrate->add_option("--subject", cal_subject, "subject id")->required();
    calibrate->add_option("--pose", cal_pose, "T or N")
        ->check(CLI::IsMember({"T", "N", "t", "n"}))
        ->capture_default_str();
    auto* record_start = control->add_subcommand("record-start", "start recording a BVH file, or a take");
    std::string record_path;
    bool record_take = false;
    std::string take_name, take_notes;
    auto* path_opt = record_start->add_option("--path", record_path, "BVH output path (default: the daemon's)");
    auto* take_flag =
        record_start->add_flag("--take", record_take, "start a take (raw samples + metadata)")->excludes(path_opt);
    record_start->add_option("--name", take_name, "take name (default: take-<UTC start>)")->needs(take_flag);
    record_start->add_option("--notes", take_notes, "take notes")->needs(take_flag);
    auto* record_stop = control->add_subcommand("record-stop", "stop recording the BVH file, or the take");
    bool stop_take = false;
    record_stop->add_flag("--take", stop_take, "stop the running take");
    auto* reload = control->add_subcommand("reload", "reload the configuration");

    auto* load = app.add_subcommand("load", "N subscriptions; frames, gaps, drops, latency");
    mocap::client::LoadOptions load_options;
    double load_duration_s = 5.0;
    bool load_json = false;
    load->add_option("--clients", load_options.clients, "connections")->capture_default_str();
    load->add_option("--protocol", load_options.protocol,
                     "pose (the pose port), bvh (live BVH port) or ws (the HTTP port's /ws); not with --nats")
        ->check(CLI::IsMember({"pose", "bvh", "ws"}))
        ->capture_default_str();
    load->add_option("--duration", load_duration_s, "seconds of measurement")->capture_default_str();
    load->add_flag("--json", load_json, "one JSON object");
    load->add_option("--subject", load_options.subject_ids, "subject id (repeatable; default all)");
    load->add_option("--decimation", load_options.decimation, "every n-th frame per subject")->capture_default_str();
    load->add_option("--churn-clients", load_options.churn_clients,
                     "extra connections that keep re-sending Subscribe (not measured)")
        ->capture_default_str();
    load->add_option("--churn-subjects", load_options.churn_subjects, "subject ids each churn Subscribe names")
        ->capture_default_str();
    load->add_option("--churn-pipelined", load_options.churn_pipelined, "Subscribes a churner sends at once")
        ->capture_default_str();
    load->add_option("--stalled", load_options.stalled, "extra subscribed connections that never read (not measured)")
        ->capture_default_str();

    // File exports (output_commands.hpp, docs/outputs.md).
    mocap::client::ExportOptions export_options;
    double export_timeout_s = 10.0;
    auto* record = app.add_subcommand("record", "live BVH port (7002), or the cluster (--nats) -> complete BVH file");
    auto* angles = app.add_subcommand("angles", "joint angles (pose port) -> CSV file");
    for (auto* sub_cmd : {record, angles}) {
        sub_cmd->add_option("--out", export_options.out, "output file (must not exist)")->required();
        sub_cmd->add_option("--frames", export_options.frames, "frames to write")->capture_default_str();
        sub_cmd->add_option("--subject", export_options.subject, "subject id (default: the server's choice / all)");
        sub_cmd->add_option("--timeout", export_timeout_s, "give up after this many seconds without data")
            ->capture_default_str();
    }

    // Takes over the web endpoint (take_commands.hpp).
    std::string http_endpoint = "127.0.0.1:8080";
    app.add_option("--http", http_endpoint, "mocapd's web endpoint, for takes")->capture_default_str();
    mocap::client::TakeCommand take_command;
    double takes_timeout_s = 120.0;
    auto* takes = app.add_subcommand("takes", "list, download, start, stop and delete takes (web endpoint)");
    takes->add_option("--token", take_command.token, "control token for start/stop/delete (or set MOCAP_TOKEN)");
    takes->add_option("--timeout", takes_timeout_s, "seconds any socket call may take (an export can be long)")
        ->capture_default_str();
    takes->require_subcommand(1);
    auto* takes_list = takes->add_subcommand("list", "the takes, one line each");
    takes_list->add_flag("--json", take_command.json, "the daemon's JSON as is");
    auto* takes_download = takes->add_subcommand("download", "a take as raw, BVH or joint-angle CSV");
    takes_download->add_option("name", take_command.name, "take name")->required();
    takes_download->add_option("--format", take_command.format, "raw, bvh or csv")
        ->check(CLI::IsMember({"raw", "bvh", "csv"}))
        ->capture_default_str();
    takes_download->add_option("--filter", take_command.filter, "bvh/csv: re-solve with this filter");
    takes_download->add_flag("--offline", take_command.offline,
                             "bvh/csv: the non-causal re-solve (forward and backward over the whole take)");
    takes_download->add_option("--subject", take_command.subject, "bvh: the subject (default: the daemon's rule)");
    takes_download->add_option("-o,--out", take_command.out, "output file (default: NAME.<format>; must not exist)");
    auto* takes_start = takes->add_subcommand("start", "start a take");
    takes_start->add_option("--name", take_command.name, "take name (default: take-<UTC start>)");
    takes_start->add_option("--notes", take_command.notes, "free text kept with the take");
    takes->add_subcommand("stop", "stop the running take");
    auto* takes_delete = takes->add_subcommand("delete", "delete a take");
    takes_delete->add_option("name", take_command.name, "take name")->required();

    CLI11_PARSE(app, argc, argv);

    std::string error;
    if (*takes) {
        const auto http = mocap::client::parse_endpoint(http_endpoint, error);
        if (!http) {
            std::cerr << "mocap-client: --http: " << error << "\n";
            return kExitConnection;
        }
        take_command.host = http->host;
        take_command.port = http->port;
        take_command.action = takes->get_subcommands().front()->get_name();
        take_command.timeout = std::chrono::milliseconds(static_cast<long long>(takes_timeout_s * 1000));
        if (take_command.token.empty()) {
            // Single-threaded here: no other thread exists yet to change the environment.
            // NOLINTNEXTLINE(concurrency-mt-unsafe)
            if (const char* env = std::getenv("MOCAP_TOKEN")) take_command.token = env;
        }
        return mocap::client::run_takes(take_command);
    }
    const auto connect_timeout = std::chrono::milliseconds(static_cast<long long>(connect_timeout_s * 1000));
    export_options.timeout = std::chrono::milliseconds(static_cast<long long>(export_timeout_s * 1000));
    if (*load) {
        load_options.duration = std::chrono::milliseconds(static_cast<long long>(load_duration_s * 1000));
        load_options.connect_timeout = connect_timeout;
    }
    if (!nats.url.empty()) {
        if (!*cat && !*load && !*record) {
            std::cerr << "mocap-client: --nats serves cat, load and record only\n";
            return kExitFailed;
        }
        if (nats.password.empty()) {
            // Single-threaded here: no other thread exists yet to change the environment.
            // NOLINTNEXTLINE(concurrency-mt-unsafe)
            if (const char* env = std::getenv("MOCAP_NATS_PASSWORD")) nats.password = env;
        }
        if (*load && (load_options.stalled > 0 || load_options.churn_clients > 0)) {
            std::cerr << "mocap-client: --stalled and --churn-clients test the pose service; not with --nats\n";
            return kExitFailed;
        }
        if (*load && load_options.protocol != "pose") {
            std::cerr << "mocap-client: --protocol bvh|ws reads mocapd's ports; not with --nats\n";
            return kExitFailed;
        }
        if (*load) return print_load(mocap::client::run_nats_load(nats, load_options), load_options, load_json);
        if (*record) return mocap::client::run_record_bvh_nats(nats, export_options);
        mocap::client::NatsPoseClient client;
        if (!client.connect(nats, connect_timeout, error)) {
            std::cerr << "mocap-client: " << error << "\n";
            return kExitConnection;
        }
        sub.fields = parse_fields(field_names);
        return run_cat(client, sub, cat_frames, cat_json, cat_idle_s);
    }
    const auto endpoint = mocap::client::parse_endpoint(connect, error);
    if (!endpoint) {
        std::cerr << "mocap-client: --connect: " << error << "\n";
        return kExitConnection;
    }

    if (*record || *angles) {
        export_options.host = endpoint->host;
        export_options.port = endpoint->port;
        return *record ? mocap::client::run_record_bvh(export_options) : mocap::client::run_angles_csv(export_options);
    }
    if (*load) {
        load_options.host = endpoint->host;
        load_options.port = endpoint->port;
        return print_load(mocap::client::run_load(load_options), load_options, load_json);
    }

    PoseClient client;
    if (!client.connect(endpoint->host, endpoint->port, connect_timeout, error)) {
        std::cerr << "mocap-client: " << error << "\n";
        return kExitConnection;
    }
    if (*cat) {
        sub.fields = parse_fields(field_names);
        return run_cat(client, sub, cat_frames, cat_json, cat_idle_s);
    }
    if (*stats) return run_stats(client, stats_json);

    if (token.empty()) {
        // Single-threaded here: no other thread exists yet to change the environment.
        // NOLINTNEXTLINE(concurrency-mt-unsafe)
        if (const char* env = std::getenv("MOCAP_TOKEN")) token = env;
    }
    v1::ControlRequest request;
    request.set_token(token);
    if (*calibrate) {
        request.mutable_calibrate()->set_subject_id(cal_subject);
        request.mutable_calibrate()->set_pose(cal_pose == "N" || cal_pose == "n" ? v1::POSE_N : v1::POSE_T);
    } else if (*record_start) {
        auto* start = request.mutable_start_recording();
        start->set_path(record_path);
        start->set_take(record_take);
        start->set_take_name(take_name);
        start->set_notes(take_notes);
    } else if (*record_stop) {
        request.mutable_stop_recording()->set_take(stop_take);
    } else if (*reload) {
        request.mutable_reload();
    }
    return run_control(client, request);
}

int main(int argc, char** argv) {
    return mocap::guarded_main("mocap-client", [&] { return run(argc, argv); });
}
