// vmc_osc.hpp — one VMC frame as one OSC bundle, encoded with liblo (docs/outputs.md, "VMC
// (live link to Unity, Blender, VTuber apps)").
//
// The bundle (timetag "immediately") holds, in this order:
//   /VMC/Ext/Root/Pos  s "root", f px py pz, f qx qy qz qw
//   /VMC/Ext/Bone/Pos  s <HumanBodyBones name>, f px py pz, f qx qy qz qw   (one per bone)
//   /VMC/Ext/OK        i loaded (1), i calibration state (3 calibrated, 0 not),
//                      i calibration mode (0 normal), i tracking (1 every sent segment fresh, 0 not)
//   /VMC/Ext/T         f seconds since the output's first frame
// so 3 + bones messages per frame (18 for the default body).
//
// Thread-safety: pure; any thread. Cost: liblo builds each message on the heap, so one call
// allocates (~40 small blocks for 15 bones); measured in docs/outputs.md. Meant for the VMC
// sender's own thread, never the pipeline's.
#pragma once

#include <cstddef>
#include <vector>

#include "serve/vmc_rig.hpp"

namespace mocap::serve {

struct VmcStatus {
    bool calibrated = false;  ///< the root segment carries a sensor-to-segment calibration
    bool tracking = false;    ///< every sent segment had a fresh sample this frame
    float time_s = 0.0f;      ///< /VMC/Ext/T
};

/// Writes the bundle into `out` (resized to its length). False when liblo failed (out of memory).
bool encode_vmc_bundle(const VmcRig& rig, const VmcPose& pose, const VmcStatus& status, std::vector<char>& out);

}  // namespace mocap::serve
