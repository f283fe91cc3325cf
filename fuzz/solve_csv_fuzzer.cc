// The two files `facedyn solve run|apply` read from other tools (solve/solve_io.h): a labelled
// markers CSV (what marker systems export) and a weights CSV, both onto a small hand-made
// puppet (3 markers, 2 channels), so the target needs no face rig.
#include <Eigen/Core>
#include <cmath>
#include <cstddef>
#include <cstdint>

#include "fuzz/fuzz_util.h"
#include "solve/solve_io.h"

namespace {

const facedyn::solve::Puppet& SmallPuppet() {
  static const facedyn::solve::Puppet* puppet = [] {
    auto* p = new facedyn::solve::Puppet();
    p->rig_name = "fuzz";
    p->channel_names = {"smile", "jaw_open"};
    p->marker_names = {"m0", "m1", "m2"};
    p->marker_vertices = {0, 1, 2};
    p->neutral_markers_in_skull = Eigen::Matrix3Xd::Identity(3, 3);
    p->marker_basis_mm = Eigen::MatrixXd::Ones(9, 2);
    p->lower_bounds = Eigen::VectorXd::Zero(2);
    p->upper_bounds = Eigen::VectorXd::Ones(2);
    return p;
  }();
  return *puppet;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const facedyn::solve::Puppet& puppet = SmallPuppet();
  const std::string path = facedyn::fuzz::WriteScratchFile("input.csv", data, size);
  const auto markers = facedyn::solve::ReadMarkersCsv(path, puppet);
  if (markers.ok()) {
    // What the reader accepts is one column per time, in the puppet's marker order, finite
    // where present.
    const auto n = static_cast<Eigen::Index>(markers->time_s.size());
    if (markers->markers_in_skull.rows() != 3 * puppet.marker_count() ||
        markers->markers_in_skull.cols() != n || markers->present.rows() != puppet.marker_count() ||
        markers->present.cols() != n) {
      __builtin_trap();
    }
    for (Eigen::Index f = 0; f < n; ++f) {
      for (int m = 0; m < puppet.marker_count(); ++m) {
        if (markers->present(m, f) &&
            !markers->markers_in_skull.block<3, 1>(3 * m, f).allFinite()) {
          __builtin_trap();
        }
      }
    }
  }
  std::vector<double> time_s;
  const auto weights = facedyn::solve::ReadWeightsCsv(path, puppet, &time_s);
  if (weights.ok() && (weights->rows() != puppet.channel_count() ||
                       weights->cols() != static_cast<Eigen::Index>(time_s.size()))) {
    __builtin_trap();
  }
  return 0;
}
