// recording_csv.hpp — the benchmark CSV of one sensor, read and written (docs/design.md, "Command-line contracts").
//
// Input header: t,gx,gy,gz,ax,ay,az,mx,my,mz and optionally qw,qx,qy,qz (reference
// orientation) and movement (0/1: samples to evaluate), in any order; unknown columns are
// ignored. t in seconds (strictly increasing), gyro rad/s, accel m/s² (specific force),
// mag µT. A magnetometer value written as `nan` marks the sample as having no magnetometer
// reading (kImuNoMag); a reference written as `nan` marks an instant without reference
// (BROAD does this where the optical system lost the markers); every other value must be a
// finite number, a reference quaternion unit within 1%, movement 0 or 1.
// Output of a filter run: t,qw,qx,qy,qz.
//
// The reader treats the file as untrusted: every problem is returned as a CsvError naming
// the 1-based line, never asserted. Thread-safety: pure functions. Cost: linear in the file.
#pragma once

#include <cstddef>
#include <cstdint>
#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include "core/imu_sample.hpp"
#include "math/quaternion.hpp"

namespace mocap::tools {

using math::Quat;

struct RecordingRow {
    ImuSample sample;
    Quat q_ref = Quat::Identity();  ///< reference orientation, unit (valid if has_reference
                                    ///< and ref_valid)
    bool ref_valid = false;         ///< the file had a finite reference on this line (`nan`
                                    ///< marks an instant the reference system lost)
    bool movement = true;           ///< evaluate this sample (true if there is no column)
};

struct Recording {
    bool has_reference = false;  ///< the file had qw,qx,qy,qz
    bool has_movement = false;   ///< the file had movement
    std::vector<RecordingRow> rows;
};

struct CsvError {
    std::size_t line = 0;  ///< 1-based line of the problem (1 = header)
    std::string message;

    [[nodiscard]] std::string to_string() const;  ///< "line N: message"
};

/// Parses a whole recording. Returns nullopt on success (out filled), else the first error.
std::optional<CsvError> read_recording_csv(std::istream& in, Recording& out);

/// Writes a recording with the columns it has (reference and movement only if present).
/// Returns false if the stream failed.
bool write_recording_csv(std::ostream& out, const Recording& recording);

/// One estimate per sample: t (s) and the quaternion, columns t,qw,qx,qy,qz.
struct OrientationRow {
    std::int64_t t_us = 0;
    Quat q = Quat::Identity();
};
bool write_orientation_csv(std::ostream& out, const std::vector<OrientationRow>& rows);

}  // namespace mocap::tools
