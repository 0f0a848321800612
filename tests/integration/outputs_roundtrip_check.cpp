// outputs_roundtrip_check — how well a BVH written by mocapd reproduces the motion that
// drove the sensors (the CMU clip, through `mocap-sim stream --truth-poses`).
//
//   outputs_roundtrip_check --truth-poses TRUTH.csv --bvh OUT.bvh --angles OUT.csv
//                           [--subject 1] [--skip-s S] [--max-rms-deg D] [--exclude SEGMENT]...
//
// BVH frame i is matched to row i of the joint-angle CSV written by the same run (same
// subject), whose t_s is the frame's sample instant; the truth row of each segment with
// the nearest t_us (within 5 ms) is its reference q_earth_segment. The BVH is read back with
// the strict reader (skeleton/bvh.hpp): each joint's global orientation is the segment's
// q_world_segment. The output world is heading-aligned at calibration, so one constant
// heading offset (the yaw of the Markley average of q_bvh ⊗ conj(q_truth) over every
// segment and frame) is removed; the error is the total angle 2·acos|w| of
// conj(q_yaw) ⊗ q_bvh ⊗ conj(q_truth). Frames before --skip-s (still calibration period,
// filter start) are not evaluated. Prints one JSON object; exit 1 if the RMS over the
// segments not --exclude'd exceeds --max-rms-deg or nothing could be matched.
// Set ROUNDTRIP_TRACE=1 to print every (segment, error) pair on stderr.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "math/markley_average.hpp"
#include "skeleton/bvh.hpp"

namespace {

using mocap::skeleton::Quat;
using mocap::skeleton::Vec3;
constexpr double kRadToDeg = 57.29577951308232;

std::vector<std::string> split(const std::string& line) {
    std::vector<std::string> out;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ','))
        out.push_back(cell);
    return out;
}

struct TruthSample {
    std::int64_t t_us;
    Quat q;
};

double angle_deg(const Quat& q) {
    return 2.0 * std::acos(std::min(1.0, std::abs(q.w()))) * kRadToDeg;
}

}  // namespace

int main(int argc, char** argv) {
    std::string truth_path, bvh_path, angles_path;
    unsigned subject = 1;
    double skip_s = 0.0, max_rms_deg = 1e9;
    std::vector<std::string> excluded;
    for (int i = 1; i + 1 < argc; i += 2) {
        const std::string k = argv[i], v = argv[i + 1];
        if (k == "--truth-poses")
            truth_path = v;
        else if (k == "--bvh")
            bvh_path = v;
        else if (k == "--angles")
            angles_path = v;
        else if (k == "--subject")
            subject = static_cast<unsigned>(std::stoul(v));
        else if (k == "--skip-s")
            skip_s = std::stod(v);
        else if (k == "--max-rms-deg")
            max_rms_deg = std::stod(v);
        else if (k == "--exclude")
            excluded.push_back(v);
        else {
            std::cerr << "unknown option " << k << "\n";
            return 2;
        }
    }
    // Truth: segment name -> samples in time order.
    std::map<std::string, std::vector<TruthSample>> truth;
    std::int64_t truth_t0 = 0;
    {
        std::ifstream in(truth_path);
        std::string line;
        std::getline(in, line);
        const auto head = split(line);
        auto col = [&](const char* name) {
            return static_cast<std::size_t>(std::find(head.begin(), head.end(), name) - head.begin());
        };
        const std::size_t ct = col("t_us"), cs = col("subject"), cg = col("segment"), cw = col("seg_qw");
        if (cw + 3 >= head.size() || ct >= head.size() || cs >= head.size() || cg >= head.size()) {
            std::cerr << truth_path << ": missing columns\n";
            return 2;
        }
        bool first = true;
        while (std::getline(in, line)) {
            const auto c = split(line);
            if (c.size() < head.size() || std::stoul(c[cs]) != subject) continue;
            const std::int64_t t = std::stoll(c[ct]);
            if (first) truth_t0 = t, first = false;
            truth[c[cg]].push_back(
                {t, Quat(std::stod(c[cw]), std::stod(c[cw + 1]), std::stod(c[cw + 2]), std::stod(c[cw + 3]))
                        .normalized()});
        }
    }
    // Frame instants from the angles CSV (same order as the BVH lines of this subject).
    std::vector<std::int64_t> frame_t_us;
    {
        std::ifstream in(angles_path);
        std::string line;
        std::getline(in, line);
        while (std::getline(in, line)) {
            const auto c = split(line);
            if (c.size() < 3 || std::stoul(c[0]) != subject) continue;
            frame_t_us.push_back(std::llround(std::stod(c[2]) * 1e6));
        }
    }
    std::ifstream bin(bvh_path);
    std::stringstream text;
    text << bin.rdbuf();
    const auto parsed = mocap::skeleton::parse_bvh(text.str());
    if (!parsed) {
        std::cerr << bvh_path << ": " << parsed.error << "\n";
        return 1;
    }
    const auto& clip = *parsed.clip;
    if (clip.frame_count != frame_t_us.size()) {
        std::cerr << "BVH has " << clip.frame_count << " frames, the angles CSV " << frame_t_us.size() << " rows\n";
        return 1;
    }
    const std::size_t nj = clip.joints.size();
    std::vector<Quat> qj(nj);
    std::vector<Vec3> pj(nj);
    struct Pair {
        std::size_t joint;
        Quat q_bvh, q_truth;
    };
    std::vector<Pair> pairs;
    std::size_t frames_used = 0;
    for (std::size_t f = 0; f < clip.frame_count; ++f) {
        if (static_cast<double>(frame_t_us[f] - truth_t0) * 1e-6 < skip_s) continue;
        mocap::skeleton::bvh_global_pose(clip, clip.frame(f), 0.01, qj, pj);
        bool used = false;
        for (std::size_t j = 0; j < nj; ++j) {
            const auto it = truth.find(clip.joints[j].name);
            if (it == truth.end()) continue;
            const auto& v = it->second;
            const auto lb = std::lower_bound(v.begin(), v.end(), frame_t_us[f],
                                             [](const TruthSample& s, std::int64_t t) { return s.t_us < t; });
            const TruthSample* best = nullptr;
            for (auto c : {lb, lb == v.begin() ? lb : lb - 1}) {
                if (c == v.end()) continue;
                if (!best || std::llabs(c->t_us - frame_t_us[f]) < std::llabs(best->t_us - frame_t_us[f])) best = &*c;
            }
            if (!best || std::llabs(best->t_us - frame_t_us[f]) > 5000) continue;
            pairs.push_back({j, qj[j], best->q});
            used = true;
        }
        frames_used += used ? 1 : 0;
    }
    if (pairs.empty()) {
        std::cerr << "no BVH frame matched the truth\n";
        return 1;
    }
    std::vector<Quat> offsets;
    for (const auto& p : pairs)
        offsets.push_back(p.q_bvh * p.q_truth.conjugate());
    const Quat mean = mocap::math::average_quaternions(offsets);
    const Quat yaw = Quat(mean.w(), 0, 0, mean.z()).normalized();
    std::vector<double> err_all, err_nofit, err_kept;
    std::map<std::size_t, std::pair<double, std::size_t>> per_joint;
    for (const auto& p : pairs) {
        const double e = angle_deg(yaw.conjugate() * p.q_bvh * p.q_truth.conjugate());
        err_all.push_back(e);
        const auto& name = clip.joints[p.joint].name;
        if (std::find(excluded.begin(), excluded.end(), name) == excluded.end()) err_kept.push_back(e);
        err_nofit.push_back(angle_deg(p.q_bvh * p.q_truth.conjugate()));
        if (std::getenv("ROUNDTRIP_TRACE")) std::fprintf(stderr, "%s %.2f\n", clip.joints[p.joint].name.c_str(), e);
        per_joint[p.joint].first += e * e;
        per_joint[p.joint].second += 1;
    }
    auto rms = [](const std::vector<double>& v) {
        double s = 0;
        for (double x : v)
            s += x * x;
        return std::sqrt(s / static_cast<double>(v.size()));
    };
    std::vector<double> sorted = err_all;
    std::sort(sorted.begin(), sorted.end());
    const double overall = rms(err_all);
    const double kept = err_kept.empty() ? 0.0 : rms(err_kept);
    std::printf(
        "{\"frames\":%zu,\"pairs\":%zu,\"heading_offset_deg\":%.2f,\"rms_deg\":%.2f,\"median_deg\":%.2f,"
        "\"p95_deg\":%.2f,\"max_deg\":%.2f,\"rms_without_heading_fit_deg\":%.2f,"
        "\"rms_without_excluded_deg\":%.2f,\"segments\":{",
        frames_used, pairs.size(), 2.0 * std::atan2(yaw.z(), yaw.w()) * kRadToDeg, overall, sorted[sorted.size() / 2],
        sorted[sorted.size() * 95 / 100], sorted.back(), rms(err_nofit), kept);
    bool first = true;
    for (const auto& [j, acc] : per_joint) {
        std::printf("%s\"%s\":%.2f", first ? "" : ",", clip.joints[j].name.c_str(),
                    std::sqrt(acc.first / static_cast<double>(acc.second)));
        first = false;
    }
    std::printf("}}\n");
    return !err_kept.empty() && kept <= max_rms_deg ? 0 : 1;
}
