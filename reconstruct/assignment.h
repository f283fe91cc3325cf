// Minimum-cost assignment (the Hungarian method, shortest augmenting paths, O(n^2 m)).
#pragma once

#include <Eigen/Core>
#include <vector>

namespace facedyn::reconstruct {

// cost is rows x cols with rows <= cols; returns for every row the column assigned to it,
// minimising the total cost (every row gets a distinct column). Entries must be finite.
std::vector<int> SolveAssignment(const Eigen::MatrixXd& cost);

// Gated assignment of `rows` items to `cols` candidates: pairs with cost above `gate` are
// forbidden and an item may stay unassigned (at cost `gate`). Returns the column per row or -1.
std::vector<int> SolveGatedAssignment(const Eigen::MatrixXd& cost, double gate);

}  // namespace facedyn::reconstruct
