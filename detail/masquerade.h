// MasqueradeModel: fine-scale detail for sparse HMC markers (Moser, Hendler, Roble 2017,
// "Masquerade", SIGGRAPH Talks), following its final design point by point:
//   1. large-scale skin from the markers (detail/large_scale.h, prefactorised);
//   2. the pose of each marker's region: deformation gradients of the large-scale mesh
//      (detail/deformation_gradient.h) averaged over the region's triangles with a Gaussian of
//      their edge-path distance to the marker, as the 9 numbers of vec(F - I);
//   3. fine detail: local vertex offsets in frames that follow the large-scale surface;
//   4. one biharmonic RBF per marker region (not per vertex) from the region's pose to the
//      local offsets of every vertex of its soft support (detail/rbf.h), blended per vertex
//      with the region weights (detail/regions.h, sum to 1);
//   5. greedy training frames, globally (all regions' poses, the whole face's offsets) and then
//      optionally per region among the global pool (its own pose and its vertices' weighted
//      offsets). The paper: 80 of 320 frames; 40, even 20, per region.
// Apply costs one back-substitution, the deformation gradients, R small RBF evaluations and
// the blend: no per-vertex solver, so the learned part's size follows the regions, not the
// output resolution.
//
// Model file (binary, little-endian as written by this machine): "FDDETAIL" magic, uint32
// format version, subject, options, neutral mesh (positions, faces), marker layout (names,
// surface points), regions (vertices and weights, feature triangles and weights), one RBF per
// region (version 2: with its output basis), "END." trailer. Load checks every count against the
// ones before it and names what is truncated or inconsistent.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "core/face_rig.h"
#include "core/mesh.h"
#include "core/progress.h"
#include "core/status.h"
#include "detail/deformation_gradient.h"
#include "detail/large_scale.h"
#include "detail/rbf.h"
#include "detail/regions.h"
#include "detail/training_set.h"

namespace facedyn::detail {

// Version 2 added each region RBF's output basis (MasqueradeOptions::output_energy). Save writes
// version 1 when no region is compressed, so both versions load (and are round-tripped by
// tests/detail/masquerade_test).
inline constexpr int kDetailModelFormatVersion = 2;

inline constexpr double kChooseOutputEnergy = 0.0;
inline constexpr double kOutputEnergyCandidates[] = {1.0, 0.9999, 0.999, 0.99, 0.9};

struct MasqueradeOptions {
  LaplacianDeformerOptions large_scale;
  // Falloffs (mm) chosen with bench/detail_bench on the procedural face with 80 markers (about
  // 19 mm apart): narrow blend regions keep the RBFs' outputs (and memory) small, a wider pose
  // neighbourhood gives each region's RBF the context of its neighbours.
  double region_sigma_mm = 4.0;    // falloff of the region blend weights
  double feature_sigma_mm = 20.0;  // falloff of the triangles that make a region's pose
  // The pose's quadrature: triangles are grouped into patches (detail/deformation_gradient.h
  // PatchRepresentatives, cells of this side) and each patch's Gaussian weight is carried by one
  // representative triangle, which shrinks the pose table (the large-scale skin, hence F, is
  // smooth over a few mm). 0: every triangle. Training only: the table it makes is stored.
  // Chosen on the validation speech of `detail_bench --ict ... --no-hmc --seeds 2,3,4
  // --pose-cell-mm C` (C = 0, 2, 4, 8; the rule, fixed before the runs: the largest cell whose
  // uncompressed validation face error is within 2% of every triangle's on each seed): 2 mm,
  // a third of the ICT face's table; 4 and 8 mm cost 3.9% and 2.7% on one seed (README).
  double pose_cell_mm = 2.0;
  int global_frames = 80;          // greedy global selection; 0 or >= #frames: every frame
  int per_region_frames = 0;       // greedy per region among the global pool; 0: the pool
  // Each region's RBF keeps the leading principal directions of its training offsets holding
  // this fraction of their energy (detail/rbf.h CompressOutputs): 1 keeps them all (exact at
  // the training frames); less shrinks the model, whose size then follows the frames and the
  // directions kept rather than the region's vertices times the frames.
  // kChooseOutputEnergy: the smallest of kOutputEnergyCandidates whose mean vertex error on the
  // training frames the global selection left out is within 5% of the uncompressed model's (1
  // when every frame is selected).
  double output_energy = 1.0;
  Status Check() const;
};

struct MasqueradeTrainingSummary {
  std::vector<int> global_frames;  // selected frames, pick order
  double mean_frames_per_region = 0.0;
  int linear_regions = 0;                   // regions whose RBF has the linear polynomial part
  double output_energy = 1.0;               // as asked, or as chosen (kChooseOutputEnergy)
  int output_energy_validation_frames = 0;  // frames the choice was made on (0: not chosen)
  double train_s = 0.0;
};

class MasqueradeModel {
 public:
  static StatusOr<MasqueradeModel> Train(const DetailTrainingSet& set,
                                         const MasqueradeOptions& options,
                                         MasqueradeTrainingSummary* summary = nullptr);

  // Upsampled skin (3 x V, skull frame, mm) for marker positions (3 x M, same order as
  // marker_names()); optionally the large-scale skin alone. Errors name a wrong marker count
  // or non-finite input.
  Status Apply(const Eigen::Matrix3Xd& markers_mm, Eigen::Matrix3Xd* skin_mm,
               Eigen::Matrix3Xd* large_scale_mm = nullptr) const;
  // Apply to every frame of a sequence, frames spread over `threads` threads (0: the machine's
  // cores; frames are independent and Apply reads only the immutable model). Output vectors are
  // resized to the frame count; an error names the first failing frame. `progress` (optional)
  // advances once per frame.
  Status ApplyFrames(const std::vector<Eigen::Matrix3Xd>& markers_mm,
                     std::vector<Eigen::Matrix3Xd>* skins_mm,
                     std::vector<Eigen::Matrix3Xd>* large_scale_mm = nullptr, int threads = 0,
                     Progress* progress = nullptr) const;

  // OK when `marker_names` are the model's markers in its order and `vertex_count` its rig's;
  // otherwise an error naming the first marker that differs (`what` names the input).
  Status CheckCompatible(const std::vector<std::string>& marker_names, int vertex_count,
                         const std::string& what) const;

  Status Save(const std::string& path) const;
  static StatusOr<MasqueradeModel> Load(const std::string& path);

  // Bytes of what was learned: the RBFs (centres, coefficients, output bases) and the region
  // tables that blend them (vertex indices and weights) and pose them (feature triangles and
  // weights). The neutral mesh and the large-scale factorisation are left out: the
  // large-scale-only baseline needs them too. MemoryBytes() is the sum of the parts.
  struct MemoryParts {
    size_t rbf_centres = 0;
    size_t rbf_coefficients = 0;
    size_t rbf_output_bases = 0;
    size_t region_vertices = 0;
    size_t feature_triangles = 0;
    size_t total() const {
      return rbf_centres + rbf_coefficients + rbf_output_bases + region_vertices +
             feature_triangles;
    }
  };
  MemoryParts MemoryBreakdown() const;
  size_t MemoryBytes() const { return MemoryBreakdown().total(); }

  const std::string& subject() const { return subject_; }
  const std::vector<Marker>& markers() const { return markers_; }
  const MarkerRegions& regions() const { return regions_; }
  const std::vector<BiharmonicRbf>& rbfs() const { return rbfs_; }
  int vertex_count() const { return neutral_.vertex_count(); }
  const Mesh& neutral() const { return neutral_; }

  // The 9 x R region poses of a large-scale skin (vec(F - I), weighted mean per region).
  void RegionPoses(const Eigen::Matrix3Xd& large_mm, Eigen::MatrixXd* poses) const;

 private:
  Status Build();  // the parts rebuilt from the stored ones: deformer, frames, gradients
  // feature_triangles_ holding mesh triangle ids -> pose_triangles_ and indices into it.
  void IndexPoseTriangles();

  std::string subject_;
  MasqueradeOptions options_;
  Mesh neutral_;
  std::vector<Marker> markers_;
  MarkerRegions regions_;  // distances_mm is left empty after Load (not needed to apply)
  // A region's pose is the weighted sum of these triangles' vec(F - I). Normalised weights in
  // float: 8 bytes an entry, and a relative 1e-7 is far below what the pose resolves.
  struct PoseTriangle {
    int32_t triangle;
    float weight;
  };
  // Per region, ascending. PoseTriangle::triangle indexes pose_triangles_, the ascending mesh
  // triangles any region's pose uses: Apply computes F for those only.
  std::vector<std::vector<PoseTriangle>> feature_triangles_;
  std::vector<int> pose_triangles_;
  std::vector<BiharmonicRbf> rbfs_;
  LaplacianDeformer deformer_;
  TangentFrames tangent_;
  DeformationGradients gradients_;
};

}  // namespace facedyn::detail
