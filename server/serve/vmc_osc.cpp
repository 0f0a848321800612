#include "serve/vmc_osc.hpp"

#include <lo/lo.h>

#include <memory>
#include <string>

namespace mocap::serve {
namespace {

struct BundleFree {
    void operator()(lo_bundle b) const { lo_bundle_free_recursive(b); }
};

// A message owned by the bundle from the moment it is added (lo_bundle_add_message takes a
// reference; lo_bundle_free_recursive drops it).
bool add_pose(lo_bundle b, const char* path, const char* name, const VmcBonePose& p) {
    lo_message m = lo_message_new();
    if (m == nullptr) return false;
    lo_message_add_string(m, name);
    for (const float v : p.position)
        lo_message_add_float(m, v);
    for (const float v : p.rotation_xyzw)
        lo_message_add_float(m, v);
    if (lo_bundle_add_message(b, path, m) != 0) {
        lo_message_free(m);
        return false;
    }
    return true;
}

}  // namespace

bool encode_vmc_bundle(const VmcRig& rig, const VmcPose& pose, const VmcStatus& status, std::vector<char>& out) {
    const std::unique_ptr<std::remove_pointer_t<lo_bundle>, BundleFree> bundle(lo_bundle_new(LO_TT_IMMEDIATE));
    if (!bundle) return false;
    lo_bundle b = bundle.get();
    if (!add_pose(b, "/VMC/Ext/Root/Pos", "root", pose.root)) return false;
    std::string name;
    for (std::size_t i = 0; i < pose.bone_count; ++i) {
        name.assign(rig.bone_name(i));
        if (!add_pose(b, "/VMC/Ext/Bone/Pos", name.c_str(), pose.bones[i])) return false;
    }
    lo_message ok = lo_message_new();
    if (ok == nullptr) return false;
    lo_message_add_int32(ok, 1);
    lo_message_add_int32(ok, status.calibrated ? 3 : 0);
    lo_message_add_int32(ok, 0);
    lo_message_add_int32(ok, status.tracking ? 1 : 0);
    if (lo_bundle_add_message(b, "/VMC/Ext/OK", ok) != 0) {
        lo_message_free(ok);
        return false;
    }
    lo_message t = lo_message_new();
    if (t == nullptr) return false;
    lo_message_add_float(t, status.time_s);
    if (lo_bundle_add_message(b, "/VMC/Ext/T", t) != 0) {
        lo_message_free(t);
        return false;
    }
    std::size_t size = lo_bundle_length(b);
    out.resize(size);
    return lo_bundle_serialise(b, out.data(), &size) != nullptr && size == out.size();
}

}  // namespace mocap::serve
