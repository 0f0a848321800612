// The real mocap-sim and mocap-filter binaries, end to end, through their command lines.
// MOCAP_SIM_BIN and MOCAP_FILTER_BIN are the built executables (tests/clients/CMakeLists.txt).
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "math/quaternion.hpp"

namespace {

namespace fs = std::filesystem;

struct ToolRun {
    int exit_code = -1;
    std::string out;
    std::string err;
};

std::string slurp(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

class ToolsEndToEnd : public ::testing::Test {
protected:
    void SetUp() override {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        dir_ = fs::temp_directory_path() / ("mocap_tools_e2e_" + std::to_string(::getpid()) + "_" + info->name());
        fs::create_directories(dir_);
    }
    void TearDown() override { fs::remove_all(dir_); }

    fs::path path(const std::string& name) const { return dir_ / name; }

    ToolRun run(const std::string& args) const {
        const fs::path o = dir_ / "stdout.txt", e = dir_ / "stderr.txt";
        const std::string cmd = args + " > '" + o.string() + "' 2> '" + e.string() + "'";
        const int status = std::system(cmd.c_str());
        ToolRun r;
        r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
        r.out = slurp(o);
        r.err = slurp(e);
        return r;
    }

    std::string sim(const std::string& args) const { return std::string(MOCAP_SIM_BIN) + " csv " + args; }
    std::string filt(const std::string& args) const { return std::string(MOCAP_FILTER_BIN) + " " + args; }

    fs::path dir_;
};

double json_number(const std::string& json, const std::string& key) {
    const std::regex re("\"" + key + "\":(-?[0-9.eE+-]+)");
    std::smatch m;
    if (!std::regex_search(json, m, re)) {
        ADD_FAILURE() << key << " missing in " << json;
        return NAN;
    }
    return std::stod(m[1].str());
}

std::size_t count_lines(const std::string& s) {
    return static_cast<std::size_t>(std::count(s.begin(), s.end(), '\n'));
}

// First data row of t,qw,qx,qy,qz output.
mocap::math::Quat first_quat(const std::string& csv) {
    std::istringstream in(csv);
    std::string line;
    std::getline(in, line);
    std::getline(in, line);
    double t, w, x, y, z;
    char c;
    std::istringstream row(line);
    row >> t >> c >> w >> c >> x >> c >> y >> c >> z;
    return mocap::math::Quat(w, x, y, z);
}

TEST_F(ToolsEndToEnd, SimWritesTheContractFileDeterministically) {
    ASSERT_EQ(run(sim("--scenario realistic --seed 2 --out " + path("a.csv").string())).exit_code, 0);
    ASSERT_EQ(run(sim("--scenario realistic --seed 2 --out " + path("b.csv").string())).exit_code, 0);
    ASSERT_EQ(run(sim("--scenario realistic --seed 3 --out " + path("c.csv").string())).exit_code, 0);
    const std::string a = slurp(path("a.csv"));
    EXPECT_EQ(a.rfind("t,gx,gy,gz,ax,ay,az,mx,my,mz,qw,qx,qy,qz,movement\n", 0), 0u);
    EXPECT_EQ(count_lines(a), 9002u);  // header + 90 s at 100 Hz + 1
    EXPECT_EQ(a, slurp(path("b.csv")));
    EXPECT_NE(a, slurp(path("c.csv")));
    ASSERT_EQ(run(sim("--scenario fourati --out " + path("f.csv").string())).exit_code, 0);
    EXPECT_EQ(count_lines(slurp(path("f.csv"))), 6002u);

    const ToolRun bad = run(sim("--scenario nope --out " + path("x.csv").string()));
    EXPECT_NE(bad.exit_code, 0);
    EXPECT_NE(run(sim("--scenario fourati --out /nonexistent-dir/x.csv")).exit_code, 0);
}

// --scenario chain|pendulum: CHAIN.toml, one CSV per segment in the layout mocap-filter reads,
// and truth.toml; the scenario check takes the single-sensor names from the scenario code.
TEST_F(ToolsEndToEnd, SimWritesChainFilesTheFilterReads) {
    const ToolRun chain = run(sim("--scenario chain --duration 20 --out " + path("chain.toml").string()));
    ASSERT_EQ(chain.exit_code, 0) << chain.err;
    const std::string toml = slurp(path("chain.toml"));
    std::size_t joints = 0;
    for (std::size_t at = 0; (at = toml.find("[[joint]]", at)) != std::string::npos; ++at)
        ++joints;
    EXPECT_EQ(joints, 4u);
    EXPECT_NE(toml.find("type = \"2dof\""), std::string::npos) << toml;
    EXPECT_NE(slurp(path("truth.toml")).find("r_parent_m"), std::string::npos);
    for (const char* seg : {"seg1", "seg2", "seg3", "seg4", "seg5"}) {
        const std::string csv = slurp(path(std::string(seg) + ".csv"));
        EXPECT_EQ(csv.rfind("t,gx,gy,gz,ax,ay,az,mx,my,mz,qw,qx,qy,qz,movement\n", 0), 0u) << seg;
        EXPECT_EQ(count_lines(csv), 802u) << seg << ": header + 20 s at 40 Hz + 1";
    }
    const ToolRun eval = run(
        filt("--filter mocap --in " + path("seg3.csv").string() + " --out " + path("est.csv").string() + " --eval"));
    ASSERT_EQ(eval.exit_code, 0) << eval.err;
    EXPECT_TRUE(std::isfinite(json_number(eval.out, "rmse_total_deg")));

    fs::create_directories(path("pendulum"));
    const ToolRun pendulum =
        run(sim("--scenario pendulum --duration 10 --seed 4 --out " + (path("pendulum") / "p.toml").string()));
    ASSERT_EQ(pendulum.exit_code, 0) << pendulum.err;
    EXPECT_EQ(count_lines(slurp(path("pendulum") / "seg2.csv")), 1002u) << "100 Hz";
    EXPECT_NE(slurp(path("pendulum") / "truth.toml").find("axis_wander_deg"), std::string::npos);

    const ToolRun bad = run(sim("--scenario nope --out " + path("x.csv").string()));
    EXPECT_NE(bad.exit_code, 0);
    EXPECT_NE(bad.err.find("chain | pendulum | fourati | realistic"), std::string::npos) << bad.err;
    const ToolRun fixed = run(sim("--scenario realistic --rate 50 --out " + path("x.csv").string()));
    EXPECT_EQ(fixed.exit_code, 2);
    EXPECT_NE(fixed.err.find("apply to chain and pendulum"), std::string::npos) << fixed.err;
    EXPECT_NE(run(sim("--scenario chain --out /nonexistent-dir/chain.toml")).exit_code, 0);
    EXPECT_EQ(run(sim("--scenario chain --duration 5 --magnetic-env nope --out " + path("c2.toml").string())).exit_code,
              2);
}

TEST_F(ToolsEndToEnd, FilterEvaluatesASimulatedRecording) {
    const std::string in = path("in.csv").string(), out = path("out.csv").string();
    ASSERT_EQ(run(sim("--scenario realistic --seed 4 --out " + in)).exit_code, 0);
    const ToolRun r = run(filt("--filter madgwick --in " + in + " --out " + out + " --eval --skip-seconds 5"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    for (const char* key : {"rmse_total_deg", "rmse_heading_deg", "rmse_inclination_deg", "rmse_roll_deg",
                            "rmse_pitch_deg", "rmse_yaw_deg", "samples"}) {
        EXPECT_TRUE(std::isfinite(json_number(r.out, key))) << key;
    }
    EXPECT_NE(r.out.find("\"filter\":\"madgwick\""), std::string::npos) << r.out;
    EXPECT_EQ(count_lines(r.out), 1u);
    // A working MARG filter on clean MEMS data is within a few degrees; a broken pipeline
    // (frame, sign, time base) is tens of degrees off.
    EXPECT_LT(json_number(r.out, "rmse_total_deg"), 10.0);
    const double samples = json_number(r.out, "samples");
    EXPECT_GT(samples, 4000.0);  // movement = 1 after 5 s
    EXPECT_LT(samples, 8500.0);
    const std::string est = slurp(out);
    EXPECT_EQ(est.rfind("t,qw,qx,qy,qz\n", 0), 0u);
    EXPECT_EQ(count_lines(est), 9002u);
    // Without --eval nothing is printed.
    const ToolRun quiet = run(filt("--filter madgwick --in " + in + " --out " + out));
    EXPECT_EQ(quiet.exit_code, 0);
    EXPECT_TRUE(quiet.out.empty());
}

TEST_F(ToolsEndToEnd, TraceWritesFlagsAndBiasPerSampleAndChangesNothingElse) {
    const std::string in = path("in.csv").string(), out = path("out.csv").string(), out2 = path("out2.csv").string();
    const std::string trace = path("trace.csv").string();
    ASSERT_EQ(run(sim("--scenario magnetic --seed 2 --out " + in)).exit_code, 0);
    const ToolRun plain = run(filt("--filter mocap --in " + in + " --out " + out + " --eval"));
    const ToolRun traced = run(filt("--filter mocap --in " + in + " --out " + out2 + " --eval --trace " + trace));
    ASSERT_EQ(plain.exit_code, 0) << plain.err;
    ASSERT_EQ(traced.exit_code, 0) << traced.err;
    EXPECT_EQ(traced.out, plain.out);  // --eval still prints one JSON object, the same one
    EXPECT_EQ(slurp(out2), slurp(out));
    const std::string tr = slurp(trace);
    EXPECT_EQ(tr.rfind("t,rest,mag_field_disturbed,mag_heading_disturbed,mag_rejected,mag_offset_weight,bias_x,"
                       "bias_y,bias_z,mag_offset_x,mag_offset_y,mag_offset_z\n",
                       0),
              0u);
    EXPECT_EQ(count_lines(tr), 9002u);  // header + one row per sample
    // The scenario rests first (rest flag), turns the field by 39° from 37 s to 53 s (rejected)
    // and has a gyro bias of 0.5-2 °/s per axis, which the last row estimates.
    std::istringstream lines(tr);
    std::string line;
    std::getline(lines, line);
    int rest = 0, rejected_in_disturbance = 0, rejected_before = 0;
    double bias_norm = 0.0;
    while (std::getline(lines, line)) {
        std::istringstream row(line);
        std::vector<double> v;
        for (std::string cell; std::getline(row, cell, ',');)
            v.push_back(std::stod(cell));
        ASSERT_EQ(v.size(), 12u) << line;
        rest += v[1] != 0.0;
        if (v[0] > 40.0 && v[0] < 52.0) rejected_in_disturbance += v[4] != 0.0;
        if (v[0] > 10.0 && v[0] < 35.0) rejected_before += v[4] != 0.0;
        bias_norm = std::hypot(v[6], v[7], v[8]);
    }
    EXPECT_GT(rest, 100);
    EXPECT_GT(rejected_in_disturbance, 1000);  // most of the 12 s at 100 Hz
    EXPECT_EQ(rejected_before, 0);
    EXPECT_GT(bias_norm, 0.5);
    // A filter without diagnostics writes zero flags; an unwritable trace is an I/O error.
    ASSERT_EQ(run(filt("--filter madgwick --in " + in + " --out " + out + " --trace " + trace)).exit_code, 0);
    EXPECT_EQ(count_lines(slurp(trace)), 9002u);
    EXPECT_EQ(run(filt("--filter mocap --in " + in + " --out " + out + " --trace /nonexistent-dir/t.csv")).exit_code,
              1);
}

TEST_F(ToolsEndToEnd, OfflineReSolvesTheWholeRecording) {
    const std::string in = path("in.csv").string(), out = path("out.csv").string();
    ASSERT_EQ(run(sim("--scenario magnetic --seed 2 --out " + in)).exit_code, 0);
    const ToolRun online = run(filt("--filter mocap --in " + in + " --out " + out + " --eval"));
    const ToolRun offline = run(filt("--filter mocap --in " + in + " --out " + out + " --eval --offline"));
    ASSERT_EQ(online.exit_code, 0) << online.err;
    ASSERT_EQ(offline.exit_code, 0) << offline.err;
    const std::string est = slurp(out);
    EXPECT_EQ(est.rfind("t,qw,qx,qy,qz\n", 0), 0u);
    EXPECT_EQ(count_lines(est), 9002u);
    EXPECT_EQ(json_number(offline.out, "samples"), json_number(online.out, "samples"));
    // Measured 0.70° against 0.98° online: the backward pass knows the heading after the 39°
    // disturbance that the forward pass has to carry through it on the gyro.
    EXPECT_LT(json_number(offline.out, "rmse_total_deg"), json_number(online.out, "rmse_total_deg") - 0.1);
    // A trace describes a causal run: asking for both is a command-line error.
    EXPECT_EQ(
        run(filt("--filter mocap --in " + in + " --out " + out + " --offline --trace " + path("trace.csv").string()))
            .exit_code,
        2);
}

TEST_F(ToolsEndToEnd, NedFrameGivesTheSameTotalErrorAndNedOutput) {
    const std::string enu_in = path("enu.csv").string(), ned_in = path("ned.csv").string();
    ASSERT_EQ(run(sim("--scenario fourati --seed 6 --out " + enu_in)).exit_code, 0);
    ASSERT_EQ(run(sim("--scenario fourati --seed 6 --frame ned --out " + ned_in)).exit_code, 0);
    const ToolRun a = run(filt("--filter madgwick --in " + enu_in + " --out " + path("a.csv").string() + " --eval"));
    const ToolRun b =
        run(filt("--filter madgwick --frame ned --in " + ned_in + " --out " + path("b.csv").string() + " --eval"));
    ASSERT_EQ(a.exit_code, 0) << a.err;
    ASSERT_EQ(b.exit_code, 0) << b.err;
    for (const char* key : {"rmse_total_deg", "rmse_heading_deg", "rmse_inclination_deg"}) {
        EXPECT_NEAR(json_number(a.out, key), json_number(b.out, key), 1e-3 * json_number(a.out, key) + 1e-4) << key;
    }
    // The NED output is q_enu_ned ⊗ the ENU output.
    const auto q_enu = first_quat(slurp(path("a.csv")));
    const auto q_ned = first_quat(slurp(path("b.csv")));
    EXPECT_LT(mocap::math::angle_rad(q_ned * mocap::math::conj(mocap::math::q_enu_ned() * q_enu)), 1e-6);
    // The fourati truth starts on NED's axes: the NED file's first reference is identity.
    std::ifstream in(ned_in);
    std::string header, row;
    std::getline(in, header);
    std::getline(in, row);
    std::replace(row.begin(), row.end(), ',', ' ');
    std::istringstream fields(row);
    double v[15] = {};
    for (double& x : v)
        fields >> x;
    ASSERT_TRUE(fields) << row;
    EXPECT_LT(mocap::math::angle_rad(mocap::math::Quat(v[10], v[11], v[12], v[13])), 1e-9) << row;
}

TEST_F(ToolsEndToEnd, MalformedInputIsRejectedWithTheLine) {
    const std::string in = path("bad.csv").string(), out = path("out.csv").string();
    {
        std::ofstream f(in);
        f << "t,gx,gy,gz,ax,ay,az,mx,my,mz\n"
          << "0,0,0,0,0,0,9.81,0,20,-40\n"
          << "0.01,0,0,0,0,0,9.81,0,20\n";
    }
    ToolRun r = run(filt("--filter madgwick --in " + in + " --out " + out));
    EXPECT_EQ(r.exit_code, 1);
    EXPECT_NE(r.err.find("line 3"), std::string::npos) << r.err;
    {
        std::ofstream f(in);
        f << "t,gx,gy,gz,ax,ay,az,mx,my,mz\n"
          << "0.02,0,0,0,0,0,9.81,0,20,-40\n"
          << "0.01,0,0,0,0,0,9.81,0,20,-40\n";
    }
    r = run(filt("--filter madgwick --in " + in + " --out " + out));
    EXPECT_EQ(r.exit_code, 1);
    EXPECT_NE(r.err.find("line 3"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("time does not increase"), std::string::npos) << r.err;
    {
        std::ofstream f(in);
        f << "t,gx,gy,gz,ax,ay,az,mx,my,mz\n"
          << "0,0,0,0,0,0,9.81,0,20,-40\n";
    }
    // Runs without a reference, but cannot evaluate.
    EXPECT_EQ(run(filt("--filter madgwick --in " + in + " --out " + out)).exit_code, 0);
    r = run(filt("--filter madgwick --in " + in + " --out " + out + " --eval"));
    EXPECT_NE(r.exit_code, 0);
    EXPECT_NE(r.err.find("qw,qx,qy,qz"), std::string::npos) << r.err;
    EXPECT_NE(run(filt("--filter madgwick --in " + path("missing.csv").string() + " --out " + out)).exit_code, 0);
}

TEST_F(ToolsEndToEnd, BadFilterNameOrParamsAreCommandLineErrors) {
    const std::string in = path("in.csv").string(), out = path("out.csv").string();
    ASSERT_EQ(run(sim("--scenario fourati --out " + in)).exit_code, 0);
    EXPECT_EQ(run(filt("--filter no-such-filter --in " + in + " --out " + out)).exit_code, 2);
    EXPECT_EQ(run(filt("--filter madgwick --param beta --in " + in + " --out " + out)).exit_code, 2);
    EXPECT_EQ(run(filt("--filter madgwick --param no_such_key=1 --in " + in + " --out " + out)).exit_code, 2);
    EXPECT_EQ(run(filt("--filter madgwick --param beta=abc --in " + in + " --out " + out)).exit_code, 2);
    EXPECT_NE(run(filt("--filter madgwick --frame nwu --in " + in + " --out " + out)).exit_code, 0);
    EXPECT_NE(run(filt("--filter madgwick --in " + in)).exit_code, 0);
    // --list names every filter the contract requires, with its keys.
    const ToolRun list = run(filt("--list"));
    ASSERT_EQ(list.exit_code, 0);
    for (const char* name : {"\ncsmo ", "\npf ", "\nmadgwick ", "\nmahony "}) {
        EXPECT_NE(("\n" + list.out).find(name), std::string::npos) << name << " in " << list.out;
    }
    EXPECT_NE(list.out.find(" beta="), std::string::npos);
    // A valid parameter changes the result.
    const ToolRun a = run(filt("--filter madgwick --in " + in + " --out " + out + " --eval"));
    const ToolRun b = run(filt("--filter madgwick --param beta=0.2 --in " + in + " --out " + out + " --eval"));
    ASSERT_EQ(a.exit_code, 0) << a.err;
    ASSERT_EQ(b.exit_code, 0) << b.err;
    EXPECT_NE(json_number(a.out, "rmse_total_deg"), json_number(b.out, "rmse_total_deg"));
}

}  // namespace
