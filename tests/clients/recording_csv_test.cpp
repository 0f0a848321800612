// The benchmark CSV: round trip, optional columns, and every malformed-input error with its line.
#include "filter_tool/recording_csv.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <sstream>

#include "sim/scenario.hpp"

namespace mocap::tools {
namespace {

constexpr const char* kHeader = "t,gx,gy,gz,ax,ay,az,mx,my,mz";

std::optional<CsvError> parse(const std::string& text, Recording& rec) {
    std::istringstream in(text);
    return read_recording_csv(in, rec);
}

CsvError parse_error(const std::string& text) {
    Recording rec;
    const auto err = parse(text, rec);
    EXPECT_TRUE(err.has_value()) << text;
    return err.value_or(CsvError{});
}

void expect_close(const Vec3d& a, const Vec3d& b) {
    for (std::size_t i = 0; i < 3; ++i)
        EXPECT_NEAR(a[i], b[i], 1e-8 * std::max(1.0, std::abs(b[i])));
}

TEST(RecordingCsv, RoundTripOfASimulatedRecording) {
    const sim::Scenario sc = sim::make_scenario(sim::ScenarioKind::magnetic, 5);
    Recording rec;
    rec.has_reference = true;
    rec.has_movement = true;
    for (const sim::ScenarioRow& r : sc.rows)
        rec.rows.push_back({r.sample, r.q_earth_sensor, true, r.moving});
    std::stringstream io;
    ASSERT_TRUE(write_recording_csv(io, rec));
    Recording back;
    const auto err = read_recording_csv(io, back);
    ASSERT_FALSE(err.has_value()) << err->to_string();
    ASSERT_TRUE(back.has_reference);
    ASSERT_TRUE(back.has_movement);
    ASSERT_EQ(back.rows.size(), rec.rows.size());
    for (std::size_t i = 0; i < rec.rows.size(); ++i) {
        const RecordingRow& a = back.rows[i];
        const RecordingRow& b = rec.rows[i];
        ASSERT_EQ(a.sample.t_us, b.sample.t_us);
        expect_close(a.sample.gyro_rad_s, b.sample.gyro_rad_s);
        expect_close(a.sample.accel_m_s2, b.sample.accel_m_s2);
        expect_close(a.sample.mag_ut, b.sample.mag_ut);
        ASSERT_LT(math::angle_rad(a.q_ref * math::conj(b.q_ref)), 1e-10);
        ASSERT_TRUE(a.ref_valid);
        ASSERT_EQ(a.movement, b.movement);
        ASSERT_TRUE(a.sample.has_mag());
    }
}

TEST(RecordingCsv, OptionalColumnsMayBeMissingAndOrderIsFree) {
    Recording rec;
    ASSERT_FALSE(parse(std::string(kHeader) + "\n0,1,2,3,4,5,6,7,8,9\n0.01,1,2,3,4,5,6,7,8,9\n", rec).has_value());
    EXPECT_FALSE(rec.has_reference);
    EXPECT_FALSE(rec.has_movement);
    ASSERT_EQ(rec.rows.size(), 2u);
    EXPECT_TRUE(rec.rows[0].movement);
    EXPECT_EQ(rec.rows[1].sample.t_us, 10'000);
    EXPECT_EQ(rec.rows[1].sample.accel_m_s2[2], 6.0);

    // Columns in another order, an unknown column, CRLF line ends, spaces, a blank last line.
    const std::string text =
        "movement, mz,my,mx,az,ay,ax,gz,gy,gx,qz,qy,qx,qw,extra,t\r\n"
        "1,9,8,7,6,5,4,3,2,1,0,0,0,1,hello,0.5\r\n"
        "0,9,8,7,6,5,4,3,2,1,0,0,1,0,x,0.51\r\n\n";
    ASSERT_FALSE(parse(text, rec).has_value());
    ASSERT_EQ(rec.rows.size(), 2u);
    EXPECT_TRUE(rec.has_reference && rec.has_movement);
    EXPECT_EQ(rec.rows[0].sample.t_us, 500'000);
    EXPECT_EQ(rec.rows[0].sample.gyro_rad_s[0], 1.0);
    EXPECT_EQ(rec.rows[0].sample.mag_ut[2], 9.0);
    EXPECT_TRUE(rec.rows[0].movement);
    EXPECT_FALSE(rec.rows[1].movement);
    EXPECT_EQ(rec.rows[1].q_ref.x(), 1.0);
}

TEST(RecordingCsv, NanMarksMissingMagnetometerAndReference) {
    Recording rec;
    const std::string text = std::string(kHeader) +
                             ",qw,qx,qy,qz\n"
                             "0,0,0,0,0,0,9.81,nan,nan,nan,1,0,0,0\n"
                             "0.01,0,0,0,0,0,9.81,20,0,-40,nan,nan,nan,nan\n";
    ASSERT_FALSE(parse(text, rec).has_value());
    EXPECT_FALSE(rec.rows[0].sample.has_mag());
    EXPECT_TRUE(rec.rows[0].ref_valid);
    EXPECT_TRUE(rec.rows[1].sample.has_mag());
    EXPECT_FALSE(rec.rows[1].ref_valid);
    // Written back, nan stays nan.
    std::stringstream io;
    ASSERT_TRUE(write_recording_csv(io, rec));
    Recording back;
    ASSERT_FALSE(read_recording_csv(io, back).has_value());
    EXPECT_FALSE(back.rows[0].sample.has_mag());
    EXPECT_FALSE(back.rows[1].ref_valid);
}

TEST(RecordingCsv, ErrorsNameTheLine) {
    const std::string h = std::string(kHeader) + "\n";
    const std::string ok = "0,0,0,0,0,0,9.8,20,0,-40\n";

    CsvError e = parse_error("");
    EXPECT_EQ(e.line, 1u);
    EXPECT_NE(e.message.find("header"), std::string::npos);

    e = parse_error("t,gx,gy,gz,ax,ay,az,mx,my\n" + ok);
    EXPECT_EQ(e.line, 1u);
    EXPECT_NE(e.message.find("'mz'"), std::string::npos) << e.message;

    e = parse_error(h + ok + "0.01,0,0,0,0,0,9.8,20,0\n");
    EXPECT_EQ(e.line, 3u);
    EXPECT_NE(e.message.find("expected 10 columns, found 9"), std::string::npos) << e.message;

    e = parse_error(h + ok + "0.01,0,0,0,0,0,9.8,20,0,-40,7\n");
    EXPECT_EQ(e.line, 3u);

    e = parse_error(h + "0,0,abc,0,0,0,9.8,20,0,-40\n");
    EXPECT_EQ(e.line, 2u);
    EXPECT_NE(e.message.find("'gy'"), std::string::npos) << e.message;
    EXPECT_NE(e.message.find("abc"), std::string::npos) << e.message;

    e = parse_error(h + "0,0,1.5x,0,0,0,9.8,20,0,-40\n");
    EXPECT_EQ(e.line, 2u);
    e = parse_error(h + "0,0,,0,0,0,9.8,20,0,-40\n");
    EXPECT_EQ(e.line, 2u);
    e = parse_error(h + "0,0,inf,0,0,0,9.8,20,0,-40\n");
    EXPECT_EQ(e.line, 2u);
    e = parse_error(h + "0,0,nan,0,0,0,9.8,20,0,-40\n");  // nan only allowed for mag / reference
    EXPECT_EQ(e.line, 2u);

    e = parse_error(h + ok + "0.02,0,0,0,0,0,9.8,20,0,-40\n" + "0.02,0,0,0,0,0,9.8,20,0,-40\n");
    EXPECT_EQ(e.line, 4u);
    EXPECT_NE(e.message.find("time does not increase"), std::string::npos) << e.message;
    e = parse_error(h + "1,0,0,0,0,0,9.8,20,0,-40\n" + ok);
    EXPECT_EQ(e.line, 3u);
    e = parse_error(h + "-1,0,0,0,0,0,9.8,20,0,-40\n");
    EXPECT_EQ(e.line, 2u);

    e = parse_error(std::string(kHeader) + ",qw,qx\n");
    EXPECT_EQ(e.line, 1u);
    e = parse_error(std::string(kHeader) + ",gx\n");
    EXPECT_NE(e.message.find("duplicate"), std::string::npos);
    e = parse_error(std::string(kHeader) + ",qw,qx,qy,qz\n" + "0,0,0,0,0,0,9.8,20,0,-40,2,0,0,0\n");
    EXPECT_EQ(e.line, 2u);
    EXPECT_NE(e.message.find("not unit"), std::string::npos);
    e = parse_error(std::string(kHeader) + ",movement\n" + "0,0,0,0,0,0,9.8,20,0,-40,2\n");
    EXPECT_EQ(e.line, 2u);
    e = parse_error(h);
    EXPECT_NE(e.message.find("no samples"), std::string::npos);
    EXPECT_EQ(parse_error(h + ok + "0.01,0,x,0,0,0,9.8,20,0,-40\n").to_string().rfind("line 3: ", 0), 0u);
}

TEST(RecordingCsv, OrientationOutput) {
    std::ostringstream out;
    ASSERT_TRUE(write_orientation_csv(out, {{0, Quat::Identity()}, {10'000, Quat(0.5, 0.5, 0.5, 0.5)}}));
    EXPECT_EQ(out.str(), "t,qw,qx,qy,qz\n0.000000,1,0,0,0\n0.010000,0.5,0.5,0.5,0.5\n");
}

}  // namespace
}  // namespace mocap::tools
