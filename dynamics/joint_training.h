// F and H trained together (Zoss et al. 2020, section 8.1: "chain F and H with cycle
// consistency"; issue 20). F has supervision only where the expression is held, so on a
// performance it cannot tell an expression's velocity from jiggle. H predicts a frame's
// offsets from the head motion and the quasistatic expression, never from the skin's
// velocity. Chained, F removes a performance's dynamics, H puts them back from F's quasistatic
// and the skull motion, and the captured take's reconstruction x - F + H = x is a loss that
// needs no target: it holds exactly when H's offsets equal F's. So performances, which have
// no target, train F (and H) through the two networks' agreement.
//
// TrainJoint:
//   1. F on the held takes, as TrainRemoval (its targets, weights, validation split);
//   2. H on the held takes decomposed by that F (RemoveDynamics), as TrainSynthesis: the
//      paper's pipeline;
//   3. both fine-tuned together (learn::TrainMlpPair): each network's own supervised loss on
//      its rows of 1-2, plus cycle_weight times the mean squared difference of F's and H's
//      sample offsets (mm^2) on the performances' frames.
//
// H's input in the cycle is the stretch S(t) of step 1's quasistatic estimate of the
// performance, held fixed during step 3: the gradient through the stretch (a change of F's
// offsets changes the quasistatic skin H sees) is dropped. The offsets are a few tenths of a
// millimetre against uv steps of 2 mm, so S moves by about 1e-4 with them.
//
// Nothing here reads a take's truth: the held takes' targets are TrainRemoval's (estimated,
// or a twin take's own quasistatic), and the performances give only their positions and poses.
#pragma once

#include <vector>

#include "core/status.h"
#include "dynamics/removal_model.h"
#include "dynamics/synthesis_model.h"
#include "learn/mlp.h"

namespace facedyn::dynamics {

struct JointTrainOptions {
  RemovalTrainOptions removal;      // step 1
  SynthesisTrainOptions synthesis;  // step 2
  // Step 3. Its batches: F's rows (frame samples) and H's (frames) as their own trainers'
  // batch sizes by default; pair_batch performance frames (each S of F's rows and one of H's).
  learn::MlpPairTrainOptions joint = JointDefaults();
  // Fraction of the performances' usable frames held out (contiguous blocks with a gap, as
  // the other trainers) to report the cycle's validation loss.
  double performance_validation_fraction = 0.1;
  // Each part's Check, the fraction in [0, 0.9]. Names the part.
  Status Check() const;

  static learn::MlpPairTrainOptions JointDefaults() {
    learn::MlpPairTrainOptions joint;
    joint.steps = 2000;
    joint.steps_per_report = 100;
    joint.learning_rate = 1e-4;
    joint.first_batch = 10000;
    joint.second_batch = 50;
    joint.pair_batch = 32;
    joint.pair_weight = 1.0;
    joint.progress_label = "train-joint";
    return joint;
  }
};

struct JointTrainSummary {
  learn::MlpTrainSummary removal;          // step 1
  learn::MlpTrainSummary synthesis;        // step 2
  learn::MlpPairTrainSummary joint;        // step 3: F's, H's and the cycle's losses per report
  long performance_frames = 0;             // cycle rows trained on
  long performance_validation_frames = 0;  // cycle rows held out
};

struct JointModels {
  RemovalModel removal;
  SynthesisModel synthesis;
};

// `held`: held-expression takes as TrainRemoval takes them (targets and weights honoured).
// `performances`: takes of any head motion and expression (talking, walking), with neither
// targets nor weights. All on one rig layout and frame rate. Errors: no held takes, no
// performances, a performance with no frame whose feature window lies inside it, and every
// error of TrainRemoval and TrainSynthesis, with the take named.
StatusOr<JointModels> TrainJoint(const std::vector<TrainingTake>& held,
                                 const std::vector<TrainingTake>& performances,
                                 const JointTrainOptions& options,
                                 JointTrainSummary* summary = nullptr);

// Step 3 alone, on an F and an H already trained as steps 1-2 would train them (e.g. by
// TrainRemoval and TrainSynthesis on F's decomposition of `held`, as the demo does), so a
// caller that keeps the separately trained pair for comparison does not train it twice. The
// held takes and options.removal / options.synthesis give each network's supervised rows,
// exactly as TrainJoint's; options.removal.train and options.synthesis.train are not used to
// train. summary->removal and summary->synthesis stay empty. Errors: as TrainJoint, and
// InvalidArgument when a given network's input layout (inputs, samples, window, fps) is not
// that of the rows its options make.
StatusOr<JointModels> FineTuneJoint(const std::vector<TrainingTake>& held,
                                    const std::vector<TrainingTake>& performances, RemovalModel f,
                                    SynthesisModel h, const JointTrainOptions& options,
                                    JointTrainSummary* summary = nullptr);

}  // namespace facedyn::dynamics
