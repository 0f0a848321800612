// chain_param.hpp — the chain stage's parameters (fusion::ChainParams) from key=value text,
// for `mocap-filter --chain --chain-param` studies. Keys are the field names of ChainParams
// and of its HeadingFilterParams (filter.<name>). Untrusted input: a bad key or value comes
// back as a message, never thrown. Pure functions.
#pragma once

#include <string>

#include "filter/filter_factory.hpp"
#include "fusion/chain_estimator.hpp"

namespace mocap::tools {

/// Applies the pairs in order; the message names the first bad key or value (empty = all set).
std::string apply_chain_params(const filter::FilterParamList& pairs, fusion::ChainParams& params);

/// The keys, comma-separated, for --help.
std::string chain_param_keys();

}  // namespace mocap::tools
