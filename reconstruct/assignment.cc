#include "reconstruct/assignment.h"

#include <limits>

#include "core/check.h"

namespace facedyn::reconstruct {

std::vector<int> SolveAssignment(const Eigen::MatrixXd& cost) {
  const int n = static_cast<int>(cost.rows());
  const int m = static_cast<int>(cost.cols());
  FACEDYN_CHECK(n <= m, "SolveAssignment needs rows <= cols");
  if (n == 0) return {};
  const double inf = std::numeric_limits<double>::infinity();
  // Potentials u (rows), v (cols); p[j] = row matched to column j (1-based, 0 = none).
  std::vector<double> u(n + 1, 0.0), v(m + 1, 0.0);
  std::vector<int> p(m + 1, 0), way(m + 1, 0);
  for (int i = 1; i <= n; ++i) {
    p[0] = i;
    int j0 = 0;
    std::vector<double> minv(m + 1, inf);
    std::vector<char> used(m + 1, 0);
    do {
      used[j0] = 1;
      const int i0 = p[j0];
      double delta = inf;
      int j1 = 0;
      for (int j = 1; j <= m; ++j) {
        if (used[j]) continue;
        const double current = cost(i0 - 1, j - 1) - u[i0] - v[j];
        if (current < minv[j]) {
          minv[j] = current;
          way[j] = j0;
        }
        if (minv[j] < delta) {
          delta = minv[j];
          j1 = j;
        }
      }
      for (int j = 0; j <= m; ++j) {
        if (used[j]) {
          u[p[j]] += delta;
          v[j] -= delta;
        } else {
          minv[j] -= delta;
        }
      }
      j0 = j1;
    } while (p[j0] != 0);
    do {
      const int j1 = way[j0];
      p[j0] = p[j1];
      j0 = j1;
    } while (j0 != 0);
  }
  std::vector<int> assignment(n, -1);
  for (int j = 1; j <= m; ++j) {
    if (p[j] != 0) assignment[p[j] - 1] = j - 1;
  }
  return assignment;
}

std::vector<int> SolveGatedAssignment(const Eigen::MatrixXd& cost, double gate) {
  const int n = static_cast<int>(cost.rows());
  const int m = static_cast<int>(cost.cols());
  // Columns: the m real candidates plus one private "unassigned" column per row at cost gate;
  // forbidden pairs cost more than leaving both unassigned.
  Eigen::MatrixXd extended = Eigen::MatrixXd::Constant(n, m + n, 4.0 * gate + 1.0);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < m; ++j) {
      if (cost(i, j) <= gate) extended(i, j) = cost(i, j);
    }
    extended(i, m + i) = gate;
  }
  std::vector<int> assignment = SolveAssignment(extended);
  for (int i = 0; i < n; ++i) {
    if (assignment[i] >= m || cost(i, assignment[i]) > gate) assignment[i] = -1;
  }
  return assignment;
}

}  // namespace facedyn::reconstruct
