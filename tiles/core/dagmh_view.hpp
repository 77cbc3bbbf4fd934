// The validated view (dagmh_traverse.hpp) behind a DAG-MH evaluator, for callers that run
// several trees' walks in lockstep (StackMap::lit_samples).
#pragma once
#include "tiles/core/dagmh_traverse.hpp"
#include "tiles/core/evaluator.hpp"

namespace st {

// The view of an evaluator open_dagmh made (its lookups' own walk), or nullptr for any
// other evaluator (MMH, a plane tile). Valid while the evaluator lives.
const dagmh::View* dagmh_view(const Evaluator& ev) noexcept;

}  // namespace st
