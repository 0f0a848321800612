// stream_command.cpp — why one thread: a load generator that needs several cores to load one
// daemon on the same host would measure itself. Each SYNC costs one pose evaluation per
// subject and a few hundred ns per node; the rest is the sink core and one send() per packet.
#include "sim/stream_command.hpp"

#include <sys/resource.h>
#include <time.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <memory>
#include <numbers>
#include <optional>

#include "core/parse_number.hpp"
#include "mocap_wire/mw_can.h"
#include "sim/magnetic_env.hpp"
#include "sim/sim_rng.hpp"
#include "sim/stream_motion.hpp"
#include "sim/stream_node.hpp"
#include "sim/stream_truth.hpp"
#include "sim/stream_uplink.hpp"
#include "sink_node/sink_node.h"
#include "skeleton/body_model.hpp"

namespace mocap::sim {
namespace {

std::atomic<bool> g_stop{false};
extern "C" void on_stop_signal(int) {
    g_stop.store(true);
}

std::uint64_t realtime_us() {
    timespec ts{};
    clock_gettime(CLOCK_REALTIME, &ts);
    return static_cast<std::uint64_t>(ts.tv_sec) * 1'000'000u + static_cast<std::uint64_t>(ts.tv_nsec) / 1000u;
}

void sleep_until_us(std::uint64_t t_us) {
    timespec ts{};
    ts.tv_sec = static_cast<time_t>(t_us / 1'000'000u);
    ts.tv_nsec = static_cast<long>((t_us % 1'000'000u) * 1000u);
    while (clock_nanosleep(CLOCK_REALTIME, TIMER_ABSTIME, &ts, nullptr) == EINTR && !g_stop.load()) {
    }
}

double cpu_seconds() {
    rusage ru{};
    getrusage(RUSAGE_SELF, &ru);
    return static_cast<double>(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
           1e-6 * static_cast<double>(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
}

struct Shared {
    const StreamCommandOptions* options = nullptr;
    const StreamMotion* motion = nullptr;
    const MagneticEnv* env = nullptr;
    std::vector<NodeDropout> dropouts;
    std::vector<std::pair<int, double>> magnets;  // (segment index, µT)
    bool attitude = false;
    double dt_s = 0.01;
    std::FILE* truth_angles = nullptr;
    std::FILE* truth_poses = nullptr;
};

struct PendingFrame {
    std::uint64_t release_us = 0;
    mw_can_frame frame{};
};

// One subject: sink core + HAL + its nodes and motion state.
class SimSink {
public:
    SimSink(const Shared& shared, int subject, const std::vector<sockaddr_in>& hosts)
        : shared_(shared),
          subject_(subject),
          host_count_(hosts.size()),
          uplink_(hosts),
          rng_(shared.options->seed, 1000u + static_cast<unsigned>(subject)),
          truth_angles_(shared.motion->model()) {
        const StreamCommandOptions& o = *shared.options;
        SimRng placement(o.seed, 2000u + static_cast<unsigned>(subject));
        heading_rad_ = placement.uniform(-std::numbers::pi, std::numbers::pi);
        origin_m_ = Vec3(10.0 * (subject - 1), 0.0, 0.0);
        const NodeSensorNoise noise = stream_node_noise(o.noise_scale);
        const auto& model = shared.motion->model();
        for (int j = 0; j < o.nodes; ++j) {
            const auto& seg = model.segments[static_cast<std::size_t>(j)];
            nodes_.emplace_back(static_cast<std::uint8_t>(seg.node_id), seg.parent < 0, o.seed,
                                static_cast<std::uint64_t>(subject) * 64u + static_cast<std::uint64_t>(seg.node_id),
                                noise);
            for (const auto& [segment, field_ut] : shared.magnets) {
                if (segment != j) continue;
                SimRng magnet(o.seed, 0x4D41474E00000000ull ^ (static_cast<std::uint64_t>(subject) * 64u +
                                                               static_cast<std::uint64_t>(seg.node_id)));
                Vec3 dir(magnet.normal(), magnet.normal(), magnet.normal());
                nodes_.back().set_hard_iron_ut(field_ut * dir.normalized());
            }
        }
        last_sample_.resize(nodes_.size());
        pending_.resize(static_cast<std::size_t>(o.nodes) * 3u * 8u);
        core_ = std::make_unique<sink_node>();
    }

    bool start() {
        const StreamCommandOptions& o = *shared_.options;
        sink_node_config config;
        sink_node_default_config(&config);
        config.sink_id = static_cast<std::uint8_t>(subject_);
        config.rate_hz = static_cast<std::uint16_t>(o.rate_hz);
        config.node_config.rate_hz = config.rate_hz;
        config.node_config.mode = shared_.attitude ? MW_MODE_ATTITUDE : MW_MODE_RAW;
        config.backoff_min_us = 100'000u;
        config.backoff_max_us = 2'000'000u;
        config.connect_timeout_us = 3'000'000u;
        config.early_close = o.early_close ? 1u : 0u;
        config.host_count = static_cast<std::uint8_t>(host_count_);
        sink_node_hal hal{};
        hal.user = this;
        hal.can_transmit = [](void* u, const mw_can_frame* f) { return static_cast<SimSink*>(u)->can_transmit(*f); };
        hal.can_receive = [](void* u, mw_can_frame* f) { return static_cast<SimSink*>(u)->can_receive(*f); };
        hal.time_us = [](void*) { return realtime_us(); };
        hal.uplink_connect = [](void* u, std::uint8_t host) { return static_cast<SimSink*>(u)->uplink_.connect(host); };
        hal.uplink_read = [](void* u, std::uint8_t* d, std::size_t cap) {
            return static_cast<SimSink*>(u)->uplink_.read(d, cap);
        };
        hal.uplink_state = [](void* u) { return static_cast<SimSink*>(u)->uplink_.state(); };
        hal.uplink_write = [](void* u, const std::uint8_t* d, std::size_t n) {
            return static_cast<SimSink*>(u)->uplink_.write(d, n);
        };
        hal.uplink_close = [](void* u) { static_cast<SimSink*>(u)->uplink_.close(); };
        hal.can_rx_lost = [](void* u) { return static_cast<SimSink*>(u)->rx_overflows_; };
        config.first_counter = o.first_counter;
        started_ = sink_node_init(core_.get(), &hal, &config) == MW_OK;
        return started_;
    }

    [[nodiscard]] bool started() const { return started_; }

    std::uint64_t deadline_us() const {
        std::uint64_t d = sink_node_next_deadline_us(core_.get());
        if (head_ < count_) d = std::min(d, pending_[head_].release_us);
        return d;
    }

    void poll() { sink_node_poll(core_.get()); }

    struct Stats {
        std::uint64_t samples = 0, lost_can_frames = 0, dropout_samples = 0;
    };
    const Stats& stats() const { return stats_; }
    const sink_node_counters& counters() const { return core_->counters; }
    int subject() const { return subject_; }

private:
    int can_transmit(const mw_can_frame& frame) {
        mw_sync sync{};
        if (frame.id == MW_CAN_ID_SYNC && mw_sync_decode(&frame, &sync) == MW_OK) on_sync(sync.counter);
        return 0;  // the simulated bus is never busy
    }

    int can_receive(mw_can_frame& out) {
        if (head_ >= count_ || pending_[head_].release_us > realtime_us()) return 0;
        out = pending_[head_++].frame;
        if (head_ == count_) head_ = count_ = 0;
        return 1;
    }

    void push(std::uint64_t release_us, const mw_can_frame& frame) {
        if (count_ == pending_.size()) {
            if (head_ == 0) {
                ++rx_overflows_;  // the sink was not polled for several periods
                return;
            }
            std::move(pending_.begin() + static_cast<std::ptrdiff_t>(head_),
                      pending_.begin() + static_cast<std::ptrdiff_t>(count_), pending_.begin());
            count_ -= head_;
            head_ = 0;
        }
        std::size_t i = count_++;
        while (i > head_ && pending_[i - 1].release_us > release_us) {  // keep release order
            pending_[i] = pending_[i - 1];
            --i;
        }
        pending_[i] = {release_us, frame};
    }

    // The motion is sampled at the SYNC's real send time, not at counter × period: when the
    // loop runs late the sink core skips instants (the counter does not), and the daemon
    // integrates with the SYNC timestamps, so motion and time must agree or every filter
    // drifts. The gyro reads the mean rate since the node's previous sample (as a
    // delta-angle IMU reports it), so a late SYNC or a dropout does not turn into an
    // orientation error the filter then has to work off; prev/next, one nominal period
    // away, give the linear acceleration.
    void on_sync(std::uint32_t counter) {
        const std::uint64_t now = realtime_us();
        if (!motion_started_) {
            motion_started_ = true;
            start_us_ = now;
        }
        const double t_s = static_cast<double>(now - start_us_) * 1e-6;
        shared_.motion->pose(t_s - shared_.dt_s, heading_rad_, origin_m_, prev_);
        shared_.motion->pose(t_s, heading_rad_, origin_m_, cur_);
        shared_.motion->pose(t_s + shared_.dt_s, heading_rad_, origin_m_, next_);
        const BodyPose& prev = prev_;
        const BodyPose& cur = cur_;
        const BodyPose& next = next_;
        const double inv_dt2 = 1.0 / (shared_.dt_s * shared_.dt_s);
        const StreamCommandOptions& o = *shared_.options;
        const std::uint64_t sync = sync_.extend(counter);
        if (shared_.truth_angles != nullptr) {
            angles_row_.clear();
            truth_angles_.append_row(static_cast<std::uint32_t>(subject_), sync, static_cast<std::int64_t>(now),
                                     std::span<const Quat>(cur.q_earth_segment.data(), shared_.motion->model().size()),
                                     angles_row_);
            (void)std::fwrite(angles_row_.data(), 1, angles_row_.size(), shared_.truth_angles);  // checked at the end
        }
        const MagneticEnv& env = *shared_.env;
        mw_can_frame frames[3];
        for (std::size_t j = 0; j < nodes_.size(); ++j) {
            SimulatedNode& node = nodes_[j];
            if (shared_.truth_poses != nullptr)
                write_truth_pose(now, counter, j, cur.q_earth_segment[j] * node.q_segment_sensor());
            if (dropped_out(node.node_id(), t_s)) {
                ++stats_.dropout_samples;
                continue;
            }
            const Vec3 lin_acc =
                (next.sensor_position_m[j] - 2.0 * cur.sensor_position_m[j] + prev.sensor_position_m[j]) * inv_dt2;
            LastSample& last = last_sample_[j];
            const bool have_last = last.valid && t_s > last.t_s;
            const int n = shared_.attitude
                              ? node.attitude_frame(cur.q_earth_segment[j], counter, frames)
                              : node.raw_frames(
                                    have_last ? last.q_earth_segment : prev.q_earth_segment[j], cur.q_earth_segment[j],
                                    have_last ? t_s - last.t_s : shared_.dt_s, lin_acc, counter, frames,
                                    env.uniform() ? env.earth_field_ut() : env.field_ut(cur.sensor_position_m[j]));
            last = {true, t_s, cur.q_earth_segment[j]};
            const std::uint64_t release =
                now + (o.jitter_us > 0.0 ? static_cast<std::uint64_t>(rng_.uniform(0.0, o.jitter_us)) : 0u);
            for (int f = 0; f < n; ++f) {
                if (o.loss > 0.0 && rng_.uniform() < o.loss) {
                    ++stats_.lost_can_frames;
                    continue;
                }
                push(release, frames[f]);
            }
            ++stats_.samples;
        }
    }

    bool dropped_out(int node, double t_s) const {
        for (const NodeDropout& d : shared_.dropouts) {
            if (d.node == node && t_s >= d.start_s && t_s < d.end_s) return true;
        }
        return false;
    }

    void write_truth_pose(std::uint64_t t_us, std::uint32_t counter, std::size_t j, const Quat& q_sensor) const {
        const Quat& q = cur_.q_earth_segment[j];
        const auto& seg = shared_.motion->model().segments[j];
        std::fprintf(shared_.truth_poses, "%llu,%d,%s,%d,%u,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f\n",
                     static_cast<unsigned long long>(t_us), subject_, seg.name.c_str(), seg.node_id, counter, q.w(),
                     q.x(), q.y(), q.z(), q_sensor.w(), q_sensor.x(), q_sensor.y(), q_sensor.z());
    }

    const Shared& shared_;
    int subject_;
    std::size_t host_count_;
    PosixUplink uplink_;
    SimRng rng_;  // loss and jitter draws
    double heading_rad_ = 0.0;
    Vec3 origin_m_ = Vec3::Zero();
    std::vector<SimulatedNode> nodes_;
    BodyPose prev_{}, cur_{}, next_{};
    struct LastSample {  // per node: the previous sample's time and orientation
        bool valid = false;
        double t_s = 0.0;
        Quat q_earth_segment = Quat::Identity();
    };
    std::vector<LastSample> last_sample_;
    bool motion_started_ = false;
    std::uint64_t start_us_ = 0;
    SyncExtender sync_;
    TruthAngles truth_angles_;
    std::string angles_row_;
    std::vector<PendingFrame> pending_;
    std::size_t head_ = 0, count_ = 0;
    std::uint32_t rx_overflows_ = 0;
    std::unique_ptr<sink_node> core_;
    bool started_ = false;
    Stats stats_;
};

void print_stats(const std::vector<std::unique_ptr<SimSink>>& sinks, const StreamCommandOptions& o, double elapsed_s,
                 double cpu_s) {
    std::uint64_t samples = 0, frames = 0, packets = 0, pdrop = 0, fdrop = 0, lost = 0, dropout = 0, skipped = 0,
                  early = 0;
    std::string per;
    for (const auto& s : sinks) {
        const auto& c = s->counters();
        const auto& st = s->stats();
        samples += st.samples;
        frames += c.frames_in;
        packets += c.packets_out;
        pdrop += c.packets_dropped;
        fdrop += c.frames_dropped;
        lost += st.lost_can_frames;
        dropout += st.dropout_samples;
        skipped += c.syncs_skipped;
        early += c.early_closes;
        char buf[512];
        std::snprintf(buf, sizeof buf,
                      "%s{\"subject\":%d,\"packets\":%u,\"frames\":%u,\"samples\":%llu,\"packets_dropped\":%u,"
                      "\"frames_dropped\":%u,\"lost_can_frames\":%llu,\"dropout_samples\":%llu,\"syncs_skipped\":%u,"
                      "\"early_closes\":%u,\"connects\":%u,\"disconnects\":%u,\"packets_busy\":%u,"
                      "\"keepalives_in\":%u,\"keepalive_timeouts\":%u,\"host_switches\":%u}",
                      per.empty() ? "" : ",", s->subject(), c.packets_out, c.frames_in,
                      static_cast<unsigned long long>(st.samples), c.packets_dropped, c.frames_dropped,
                      static_cast<unsigned long long>(st.lost_can_frames),
                      static_cast<unsigned long long>(st.dropout_samples), c.syncs_skipped, c.early_closes, c.connects,
                      c.disconnects, c.packets_busy, c.keepalives_in, c.keepalive_timeouts, c.host_switches);
        per += buf;
    }
    std::printf(
        "{\"subjects\":%d,\"nodes\":%d,\"rate_hz\":%d,\"mode\":\"%s\",\"elapsed_s\":%.3f,"
        "\"requested_samples_per_s\":%d,\"samples\":%llu,\"samples_per_s\":%.1f,\"can_frames\":%llu,"
        "\"packets\":%llu,\"packets_dropped\":%llu,\"frames_dropped\":%llu,\"lost_can_frames\":%llu,"
        "\"dropout_samples\":%llu,\"syncs_skipped\":%llu,\"early_closes\":%llu,\"cpu_percent\":%.1f,"
        "\"per_subject\":[%s]}\n",
        o.subjects, o.nodes, o.rate_hz, o.mode.c_str(), elapsed_s, o.subjects * o.nodes * o.rate_hz,
        static_cast<unsigned long long>(samples), elapsed_s > 0 ? static_cast<double>(samples) / elapsed_s : 0.0,
        static_cast<unsigned long long>(frames), static_cast<unsigned long long>(packets),
        static_cast<unsigned long long>(pdrop), static_cast<unsigned long long>(fdrop),
        static_cast<unsigned long long>(lost), static_cast<unsigned long long>(dropout),
        static_cast<unsigned long long>(skipped), static_cast<unsigned long long>(early),
        elapsed_s > 0 ? 100.0 * cpu_s / elapsed_s : 0.0, per.c_str());
    (void)std::fflush(stdout);  // a progress line: nothing to do if stdout is gone
}

}  // namespace

bool parse_dropout(const std::string& text, NodeDropout* out, std::string* error) {
    NodeDropout d;
    const auto f = core::split_fields(text, ':');
    if (f.size() != 3 || !core::parse_number(f[0], d.node) || !core::parse_number(f[1], d.start_s) ||
        !core::parse_number(f[2], d.end_s) || d.node < static_cast<int>(MW_NODE_ID_MIN) ||
        d.node > static_cast<int>(MW_NODE_ID_MAX) || !(d.start_s >= 0.0) || !(d.end_s > d.start_s)) {
        *error = "--dropout expects NODE:START_S:END_S with node 1..63 and 0 <= START < END, got '" + text + "'";
        return false;
    }
    *out = d;
    return true;
}

bool parse_magnet(const std::string& text, SegmentMagnet* out, std::string* error) {
    SegmentMagnet m;
    const auto f = core::split_fields(text, ':');
    bool ok = !f.empty() && f.size() <= 2 && !f[0].empty();
    if (ok) m.segment = std::string(f[0]);
    if (ok && f.size() == 2) ok = core::parse_number(f[1], m.field_ut) && m.field_ut > 0.0 && m.field_ut <= 2000.0;
    if (!ok) {
        *error = "--magnet expects SEGMENT[:UT] with 0 < UT <= 2000, got '" + text + "'";
        return false;
    }
    *out = m;
    return true;
}

CLI::App* add_stream_command(CLI::App& app, StreamCommandOptions& o) {
    CLI::App* cmd =
        app.add_subcommand("stream", "Act as K sink nodes with simulated sensor nodes, streaming to mocapd");
    cmd->add_option("--connect", o.connect,
                    "mocapd sink port HOST:PORT, or an ordered list HOST:PORT,HOST:PORT,... (up to 8): on a lost "
                    "connection, or 750 ms without the host's keepalive, each sink moves to the next host, "
                    "wrapping, at most one attempt per host per second")
        ->required();
    cmd->add_option("--subjects", o.subjects, "Subjects = sinks, sink ids FIRST..FIRST+K-1")
        ->check(CLI::Range(1, 255))
        ->capture_default_str();
    cmd->add_option("--first-sink-id", o.first_sink_id,
                    "FIRST: sink id of the first sink (several simulators, one per host, ids apart)")
        ->check(CLI::Range(1, 255))
        ->capture_default_str();
    cmd->add_option("--nodes", o.nodes, "Sensor nodes per subject (first N segments of the body)")
        ->check(CLI::Range(1, 15))
        ->capture_default_str();
    cmd->add_option("--rate", o.rate_hz, "SYNC rate, Hz")->check(CLI::Range(1, 1000))->capture_default_str();
    cmd->add_option("--mode", o.mode, "raw (ACCEL+GYRO+MAG) | quat (on-node attitude, ATT)")
        ->check(CLI::IsMember({"raw", "quat"}))
        ->capture_default_str();
    cmd->add_option("--duration", o.duration_s, "Seconds to run")->check(CLI::PositiveNumber)->capture_default_str();
    cmd->add_option("--motion", o.motion, "walk | FILE.bvh")->capture_default_str();
    cmd->add_option("--loss", o.loss, "Probability that a node CAN frame is lost")
        ->check(CLI::Range(0.0, 1.0))
        ->capture_default_str();
    cmd->add_option("--seed", o.seed, "Random seed (mounting, noise, loss, headings)")->capture_default_str();
    cmd->add_option("--truth", o.truth_path,
                    "Write the true joint angles here, in mocap-client angles' CSV format (join on sync)");
    cmd->add_option("--truth-poses", o.truth_poses_path,
                    "Write every segment's and sensor's true orientation here (CSV, one row per segment and SYNC)");
    cmd->add_option("--dropout", o.dropouts, "NODE:START_S:END_S: node silent in that window (repeatable)");
    cmd->add_option("--jitter-us", o.jitter_us, "Node answer delay drawn in [0, J] us")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    cmd->add_option("--calibrate-s", o.calibrate_s, "Seconds of still T-pose before the motion")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    cmd->add_option("--noise-scale", o.noise_scale, "Multiply every sensor noise sigma and the gyro bias (0 = ideal)")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    cmd->add_option("--magnetic-env", o.magnetic_env,
                    "Field the magnetometers read at their position: clean | lab | steel-floor | FILE.toml")
        ->capture_default_str();
    cmd->add_option("--magnet", o.magnets,
                    "SEGMENT[:UT]: a magnet on that segment adds UT uT (default 30), fixed in its sensor's frame "
                    "(repeatable)");
    cmd->add_option("--first-counter", o.first_counter, "SYNC counter of the first instant (test the 2^32 wrap)")
        ->capture_default_str();
    cmd->add_flag("--sink-rate-stats", o.sink_rate_stats, "Print one JSON line of sent/dropped counts at the end");
    cmd->add_flag("--early-close,!--no-early-close", o.early_close,
                  "Sinks send an instant's packet as soon as it is complete (default) or only at the next SYNC");
    return cmd;
}

int run_stream_command(const StreamCommandOptions& o) {
    std::string error;
    std::vector<sockaddr_in> hosts;
    if (!resolve_host_list(o.connect, SINK_NODE_MAX_HOSTS, &hosts, &error)) {
        std::fprintf(stderr, "mocap-sim stream: %s\n", error.c_str());
        return 2;
    }
    Shared shared;
    shared.options = &o;
    shared.attitude = o.mode == "quat";
    shared.dt_s = 1.0 / o.rate_hz;
    if (o.jitter_us * 1e-6 >= shared.dt_s) {
        std::fprintf(stderr, "mocap-sim stream: --jitter-us must be shorter than one sample period\n");
        return 2;
    }
    if (o.first_sink_id + o.subjects - 1 > 255) {
        std::fprintf(stderr, "mocap-sim stream: sink ids end at 255: --first-sink-id + --subjects - 1 is %d\n",
                     o.first_sink_id + o.subjects - 1);
        return 2;
    }
    for (const std::string& text : o.dropouts) {
        NodeDropout d;
        if (!parse_dropout(text, &d, &error)) {
            std::fprintf(stderr, "mocap-sim stream: %s\n", error.c_str());
            return 2;
        }
        shared.dropouts.push_back(d);
    }
    const skeleton::BodyModel model = skeleton::default_body_model();
    std::optional<StreamMotion> motion;
    if (o.motion == "walk") {
        motion = StreamMotion::walk(model, o.calibrate_s);
    } else {
        motion = StreamMotion::from_bvh_file(o.motion, model, o.calibrate_s, &error);
        if (!motion) {
            std::fprintf(stderr, "mocap-sim stream: %s\n", error.c_str());
            return 2;
        }
    }
    shared.motion = &*motion;
    const auto env = MagneticEnv::load(o.magnetic_env, o.seed, &error);
    if (!env) {
        std::fprintf(stderr, "mocap-sim stream: %s\n", error.c_str());
        return 2;
    }
    shared.env = &*env;
    for (const std::string& text : o.magnets) {
        SegmentMagnet m;
        if (!parse_magnet(text, &m, &error)) {
            std::fprintf(stderr, "mocap-sim stream: %s\n", error.c_str());
            return 2;
        }
        const int segment = model.index_of(m.segment);
        if (segment < 0 || segment >= o.nodes) {
            std::fprintf(stderr, "mocap-sim stream: --magnet: '%s' is not one of the %d segments with a node\n",
                         m.segment.c_str(), o.nodes);
            return 2;
        }
        shared.magnets.emplace_back(segment, m.field_ut);
    }

    using File = std::unique_ptr<std::FILE, int (*)(std::FILE*)>;
    auto open_truth = [](const std::string& path, char* buffer, std::size_t size, File& file) {
        file.reset(std::fopen(path.c_str(), "w"));
        if (!file) {
            std::fprintf(stderr, "mocap-sim stream: cannot write %s\n", path.c_str());
            return false;
        }
        (void)std::setvbuf(file.get(), buffer, _IOFBF, size);  // else default buffering
        return true;
    };
    File truth_angles(nullptr, &std::fclose), truth_poses(nullptr, &std::fclose);
    static char angles_buffer[1 << 20], poses_buffer[1 << 20];
    if (!o.truth_path.empty()) {
        if (!open_truth(o.truth_path, angles_buffer, sizeof angles_buffer, truth_angles)) return 2;
        const std::string header = TruthAngles(model).header();
        (void)std::fwrite(header.data(), 1, header.size(), truth_angles.get());  // checked at the end
        shared.truth_angles = truth_angles.get();
    }
    if (!o.truth_poses_path.empty()) {
        if (!open_truth(o.truth_poses_path, poses_buffer, sizeof poses_buffer, truth_poses)) return 2;
        std::fprintf(truth_poses.get(),
                     "t_us,subject,segment,node,counter,seg_qw,seg_qx,seg_qy,seg_qz,sensor_qw,sensor_qx,"
                     "sensor_qy,sensor_qz\n");
        shared.truth_poses = truth_poses.get();
    }

    std::vector<std::unique_ptr<SimSink>> sinks;
    sinks.reserve(static_cast<std::size_t>(o.subjects));
    for (int k = 0; k < o.subjects; ++k)
        sinks.push_back(std::make_unique<SimSink>(shared, o.first_sink_id + k, hosts));

    g_stop.store(false);
    std::signal(SIGINT, on_stop_signal);
    std::signal(SIGTERM, on_stop_signal);
    const double cpu0 = cpu_seconds();
    const std::uint64_t t0 = realtime_us();
    const std::uint64_t end = t0 + static_cast<std::uint64_t>(o.duration_s * 1e6);
    const std::uint64_t period_us = 1'000'000u / static_cast<std::uint64_t>(o.rate_hz);
    std::size_t started = 0;
    std::uint64_t now = t0;
    while (now < end && !g_stop.load()) {
        // Staggered start: sink i begins i/K of a period after the first.
        while (started < sinks.size() && now >= t0 + started * period_us / sinks.size()) {
            if (!sinks[started]->start()) {
                std::fprintf(stderr, "mocap-sim stream: sink core rejected the configuration (rate %d)\n", o.rate_hz);
                return 2;
            }
            ++started;
        }
        std::uint64_t next = started < sinks.size() ? t0 + started * period_us / sinks.size() : end;
        for (std::size_t i = 0; i < started; ++i) {
            SimSink& s = *sinks[i];
            if (s.deadline_us() <= now) s.poll();
            // SYNC handed out frames: poll again right away for those already released.
            std::uint64_t d = s.deadline_us();
            if (d <= now) {
                s.poll();
                d = s.deadline_us();
            }
            next = std::min(next, d);
        }
        now = realtime_us();
        if (next > now) {
            sleep_until_us(std::min(next, end));
            now = realtime_us();
        }
    }
    const double elapsed_s = static_cast<double>(realtime_us() - t0) * 1e-6;
    const double cpu_s = cpu_seconds() - cpu0;

    int rc = 0;
    for (const auto& s : sinks) {
        if (s->counters().connects == 0) {
            std::fprintf(stderr, "mocap-sim stream: subject %d never connected to %s\n", s->subject(),
                         o.connect.c_str());
            rc = 1;
        }
    }
    if (o.sink_rate_stats) print_stats(sinks, o, elapsed_s, cpu_s);
    for (const auto& [file, path] :
         {std::pair{truth_angles.get(), &o.truth_path}, {truth_poses.get(), &o.truth_poses_path}}) {
        if (file != nullptr && (std::fflush(file) != 0 || std::ferror(file) != 0)) {
            std::fprintf(stderr, "mocap-sim stream: write to %s failed\n", path->c_str());
            rc = rc == 0 ? 1 : rc;
        }
    }
    return rc;
}

}  // namespace mocap::sim
