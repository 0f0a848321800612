// config_check.hpp — the one validation path of `mocapd --check-config`, start-up and
// SIGHUP/reload: a config that passes here is one the daemon starts on.
//
// parse_config (daemon/config.hpp) checks what the text alone shows: types, ranges, choices,
// with file and line. check_config adds what needs the rest of the daemon or the host: the
// body model, every filter in use built with [filter.params] (unknown names, unknown or
// ill-typed parameters), bvh_subject and vmc.subject against the configured subjects, the
// [vmc.bones] mapping against the body model, [vmc] destinations that do not resolve (a DNS
// look-up: it may take as long as the resolver does), two listeners on one port, and
// raw_record's directory. Its errors read "<file>: <key>: <what is wrong>".
// Thread-safety: pure apart from stat() of record_dir and the look-up of [vmc] destinations;
// no sockets are opened.
#pragma once

#include <optional>
#include <string>
#include <string_view>

#include "daemon/config.hpp"

namespace mocap::daemon {

/// True if the daemon can run on `config`; else false and *error names the key.
/// `source_name` prefixes the message (the file, or "<embedded mocapd.toml>").
bool check_config(const DaemonConfig& config, std::string_view source_name, std::string* error);

/// Loads `path` (load_config_file; "" = the embedded default) and runs check_config on it:
/// what --check-config, start-up and reload all call.
std::optional<DaemonConfig> load_checked_config(const std::string& path, std::string* error);

}  // namespace mocap::daemon
