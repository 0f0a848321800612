// config_check.hpp — the one validation path of `mocapd --check-config`, start-up and
// SIGHUP/reload: a config that passes here is one the daemon starts on.
//
// parse_config (daemon/config.hpp) checks what the text alone shows: types, ranges, choices,
// with file and line. check_config adds what needs the rest of the daemon or the host: the
// body model, every filter in use built with [filter.params] (unknown names, unknown or
// ill-typed parameters), bvh_subject and vmc.subject against the configured subjects, the
// [vmc.bones] mapping against the body model, two listeners on one port, and raw_record's
// directory. Its errors read "<file>: <key>: <what is wrong>".
// Only `mocapd --check-config` also looks up the [vmc] destinations (HostLookups::kResolve):
// a name that does not resolve is a typo to an operator checking a file, but at start-up or
// reload it may be a DNS server that is not up yet (boot order) or a receiver that comes and
// goes, so the daemon starts and its VMC sender retries the look-up (vmc.resolve_errors).
// Thread-safety: pure apart from stat() of record_dir and, with kResolve, the DNS look-up of
// [vmc] destinations (it may take as long as the resolver does); no sockets are opened.
#pragma once

#include <optional>
#include <string>
#include <string_view>

#include "daemon/config.hpp"

namespace mocap::daemon {

/// Whether the check looks host names up (see the file comment).
enum class HostLookups { kSkip, kResolve };

/// True if the daemon can run on `config`; else false and *error names the key.
/// `source_name` prefixes the message (the file, or "<embedded mocapd.toml>").
bool check_config(const DaemonConfig& config, std::string_view source_name, std::string* error,
                  HostLookups lookups = HostLookups::kSkip);

/// Loads `path` (load_config_file; "" = the embedded default) and runs check_config on it:
/// what --check-config (with kResolve), start-up and reload all call.
std::optional<DaemonConfig> load_checked_config(const std::string& path, std::string* error,
                                                HostLookups lookups = HostLookups::kSkip);

}  // namespace mocap::daemon
