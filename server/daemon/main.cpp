// mocapd — entry point: command line, config, logging, then the Daemon.
#include <google/protobuf/stubs/logging.h>
#include <spdlog/spdlog.h>
#include <CLI/CLI.hpp>

#include <cstdio>
#include <iostream>

#include "core/guarded_main.hpp"
#include "daemon/config.hpp"
#include "daemon/config_check.hpp"
#include "daemon/daemon.hpp"
#include "daemon/replay.hpp"
#include "daemon/replay_args.hpp"
#include "daemon/take_args.hpp"

namespace {

// libprotobuf reports malformed client input (e.g. invalid UTF-8 in a string field) by
// printing an ERROR line itself, bypassing the sessions' log limiter: a client reconnecting
// in a loop could flood the log. The session already counts and closes such clients, so
// protobuf's own lines go to debug level.
void protobuf_log(google::protobuf::LogLevel level, const char* file, int line, const std::string& message) {
    if (level >= google::protobuf::LOGLEVEL_FATAL) {
        spdlog::critical("protobuf {}:{}: {}", file, line, message);
    } else {
        spdlog::debug("protobuf {}:{}: {}", file, line, message);
    }
}

}  // namespace

static int run(int argc, char** argv) {
    using namespace mocap::daemon;
    CLI::App app{"mocapd — networked inertial motion capture daemon"};
    std::string config_path;
    std::string check_path;
    bool print_default = false;
    app.add_option("--config", config_path, "TOML config (default: the embedded config/mocapd.toml)");
    app.add_option("--check-config", check_path, "validate FILE and exit (0 = valid)");
    app.add_flag("--print-default-config", print_default, "print the embedded default config and exit");
    // Replay of raw recordings (docs/outputs.md): no sockets, files out, then exit.
    ReplayOptions replay;
    std::vector<std::string> calibrate_at;
    std::string from_text, to_text;
    auto* replay_opt = app.add_option("--replay", replay.files,
                                      "re-run raw recording(s) or take(s) (a name in [outputs].record_dir/takes, or a "
                                      "take's directory) through the pipeline and exit");
    auto* jetstream_opt = app.add_option("--jetstream", replay.jetstream_url,
                                         "replay a take from JetStream at this NATS URL (needs --subject; credentials "
                                         "from [cluster]) and exit")
                              ->excludes(replay_opt);
    // A take served as if live (take_player.hpp): every socket as configured, no sinks.
    PlayOptions play;
    auto* play_opt = app.add_option("--play", play.files,
                                    "serve raw recording(s) or take(s) as if live (pose, BVH, viewer, VMC; no sink "
                                    "listener)")
                         ->excludes(replay_opt)
                         ->excludes(jetstream_opt);
    app.add_flag("--loop", play.loop, "with --play: start the take again after its end, forever")->needs(play_opt);
    // Replay options: with --replay FILE... or with --jetstream URL.
    std::vector<CLI::Option*> replay_only;
    replay_only.push_back(app.add_option("--site", replay.site, "replay --jetstream: site (default: [cluster].site)"));
    replay_only.push_back(
        app.add_option("--subject", replay.subject, "replay: only this subject (--jetstream: required)"));
    replay_only.push_back(
        app.add_option("--from", from_text, "replay: samples received from this time (RFC 3339 or epoch s)"));
    replay_only.push_back(
        app.add_option("--to", to_text, "replay: samples received up to this time (RFC 3339 or epoch s)"));
    replay_only.push_back(
        app.add_flag("--realtime", replay.realtime, "replay at the recorded pace (default: as fast as possible)"));
    replay_only.push_back(app.add_flag("--offline", replay.offline,
                                       "replay: re-solve each sensor's whole take forward and backward (non-causal)"));
    replay_only.push_back(app.add_option("--bvh-out", replay.bvh_out, "replay: write a BVH file (must not exist)"));
    replay_only.push_back(app.add_option("--bvh-subject", replay.bvh_subject,
                                         "replay: subject written to the BVH (0 = [outputs].bvh_subject)"));
    replay_only.push_back(
        app.add_option("--angles-out", replay.angles_out, "replay: write the joint-angle CSV (must not exist)"));
    replay_only.push_back(app.add_option("--calibration-dir", replay.calibration_dir,
                                         "replay: load/save calibrations here (default: none)"));
    replay_only.push_back(app.add_option("--calibrate-at", calibrate_at,
                                         "replay: SECONDS[:SUBJECT[:T|N]] calibrate at that sample time"));
    CLI11_PARSE(app, argc, argv);
    const bool replaying = replay_opt->count() > 0 || jetstream_opt->count() > 0;
    for (const CLI::Option* o : replay_only) {
        if (o->count() > 0 && !replaying) {
            std::cerr << "mocapd: " << o->get_name() << " requires --replay or --jetstream\n";
            return 1;
        }
    }

    if (print_default) {
        std::cout << embedded_default_config();
        return 0;
    }
    std::string error;
    // --check-config, start-up and reload (Daemon::reload) share one validation path.
    if (!check_path.empty()) {
        const auto c = load_checked_config(check_path, &error, HostLookups::kResolve);
        if (!c) {
            std::cerr << "mocapd: invalid config: " << error << "\n";
            return 1;
        }
        std::cout << check_path << ": valid\n";
        return 0;
    }
    auto config = load_checked_config(config_path, &error);
    if (!config) {
        std::cerr << "mocapd: invalid config: " << error << "\n";
        return 1;
    }
    spdlog::set_level(spdlog::level::from_str(config->log_level));
    // Logs go to stdout (journald under systemd): flush every line so nothing is held back
    // when the daemon is killed. Log lines are rare (counted events are logged once).
    spdlog::flush_on(spdlog::level::trace);
    google::protobuf::SetLogHandler(&protobuf_log);
    // Takes stand for their raw files (take_args.hpp).
    for (const auto& [what, files] : {std::pair{"replay", &replay.files}, std::pair{"play", &play.files}}) {
        if (files->empty()) continue;
        auto expanded = expand_take_args(*files, config->record_dir, &error);
        if (!expanded) {
            std::cerr << "mocapd: " << what << ": " << error << "\n";
            return 1;
        }
        *files = std::move(*expanded);
    }
    if (replaying) {
        if ((!from_text.empty() && !parse_replay_time(from_text, &replay.from_us, &error)) ||
            (!to_text.empty() && !parse_replay_time(to_text, &replay.to_us, &error))) {
            std::cerr << "mocapd: " << error << "\n";
            return 1;
        }
        for (const std::string& spec : calibrate_at) {
            ReplayCalibration c;
            if (!parse_replay_calibration(spec, &c, &error)) {
                std::cerr << "mocapd: " << error << "\n";
                return 1;
            }
            replay.calibrate.push_back(c);
        }
        ReplayResult r;
        if (!run_replay(*config, replay, &r, &error)) {
            std::cerr << "mocapd: replay: " << error << "\n";
            return 1;
        }
        std::printf(
            "replayed %llu samples (%llu unknown node, %llu rejected, %llu reordered, %llu too late) -> %llu "
            "frames, %llu BVH frames%s\n",
            static_cast<unsigned long long>(r.samples), static_cast<unsigned long long>(r.samples_unknown_node),
            static_cast<unsigned long long>(r.samples_rejected), static_cast<unsigned long long>(r.samples_reordered),
            static_cast<unsigned long long>(r.samples_too_late), static_cast<unsigned long long>(r.frames),
            static_cast<unsigned long long>(r.bvh_frames), r.truncated ? " (last record truncated)" : "");
        return 0;
    }
    Daemon daemon(*config, config_path);
    if (!play.files.empty()) daemon.play(play);
    if (!daemon.start(&error)) {
        spdlog::critical("cannot start: {}", error);
        return 1;
    }
    daemon.run();
    return 0;
}

int main(int argc, char** argv) {
    return mocap::guarded_main("mocapd", [&] { return run(argc, argv); });
}
