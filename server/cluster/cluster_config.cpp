#include "cluster/cluster_config.hpp"

#include <nats/nats.h>

#include <fstream>

namespace mocap::cluster {
namespace {

// The public user key of an nkey seed file as `nk -gen user -pubout` writes it: the seed
// ("SU...") and the public key ("U...") on their own lines. The client needs both.
std::string nkey_public_key(const std::string& path) {
    std::ifstream in(path);
    for (std::string line; std::getline(in, line);) {
        while (!line.empty() && (line.back() == '\r' || line.back() == ' '))
            line.pop_back();
        if (line.size() == 56 && line.front() == 'U') return line;
    }
    return {};
}

bool configure(const ClusterConfig& c, natsOptions* o, std::string* error) {
    if (!nats_ok(natsOptions_SetURL(o, c.nats_url.c_str()), "nats_url", error)) return false;
    const std::string client_name = "mocapd " + c.host_id;
    (void)natsOptions_SetName(o, client_name.c_str());
    // Without a deadline a server that stops reading blocks the writer for good, and with it
    // every call on the connection (the client holds its lock while it writes).
    (void)natsOptions_SetWriteDeadline(o, kNatsWriteDeadlineMs);
    if (!c.user.empty() && !nats_ok(natsOptions_SetUserInfo(o, c.user.c_str(), c.password.c_str()), "user", error))
        return false;
    if (!c.creds_file.empty() &&
        !nats_ok(natsOptions_SetUserCredentialsFromFiles(o, c.creds_file.c_str(), nullptr), "creds_file", error))
        return false;
    if (!c.nkey_seed_file.empty()) {
        const std::string pub = nkey_public_key(c.nkey_seed_file);
        if (pub.empty()) {
            *error = "cluster: nkey_seed_file " + c.nkey_seed_file + " holds no public user key (a line \"U...\")";
            return false;
        }
        if (!nats_ok(natsOptions_SetNKeyFromSeed(o, pub.c_str(), c.nkey_seed_file.c_str()), "nkey_seed_file", error))
            return false;
    }
    if (!c.tls_ca_file.empty()) {
        if (!nats_ok(natsOptions_SetSecure(o, true), "tls", error) ||
            !nats_ok(natsOptions_LoadCATrustedCertificates(o, c.tls_ca_file.c_str()), "tls_ca_file", error))
            return false;
    }
    return c.tls_cert_file.empty() ||
           nats_ok(natsOptions_LoadCertificatesChain(o, c.tls_cert_file.c_str(), c.tls_key_file.c_str()),
                   "tls_cert_file", error);
}

}  // namespace

bool nats_ok(int status, const char* what, std::string* error) {
    const auto s = static_cast<natsStatus>(status);
    if (s == NATS_OK) return true;
    *error = std::string("cluster: ") + what + ": " + natsStatus_GetText(s);
    return false;
}

std::string nats_error_text(int status) {
    std::string text = natsStatus_GetText(static_cast<natsStatus>(status));
    std::string detail = nats_GetLastError(nullptr) != nullptr ? nats_GetLastError(nullptr) : "";
    if (const auto at = detail.find("): "); detail.rfind('(', 0) == 0 && at != std::string::npos)
        detail.erase(0, at + 3);
    if (!detail.empty() && detail != text) text += ": " + detail;
    return text;
}

bool make_nats_options(const ClusterConfig& config, natsOptions** out, std::string* error) {
    *out = nullptr;
    natsOptions* o = nullptr;
    if (!nats_ok(natsOptions_Create(&o), "options", error)) return false;
    if (!configure(config, o, error)) {
        natsOptions_Destroy(o);
        return false;
    }
    *out = o;
    return true;
}

}  // namespace mocap::cluster
