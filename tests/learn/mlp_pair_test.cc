// Two networks trained together with a consistency term (learn/mlp.h, TrainMlpPair): the
// consistency rows teach the first network where it has no supervision of its own.

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "learn/mlp.h"

namespace facedyn::learn {
namespace {

using ::testing::HasSubstr;

class ColumnsDataset final : public MlpDataset {
 public:
  int input_size() const override { return static_cast<int>(inputs.rows()); }
  int output_size() const override { return static_cast<int>(targets.rows()); }
  void Gather(const long* rows, long n, Eigen::MatrixXf* x, Eigen::MatrixXf* y) const override {
    x->resize(inputs.rows(), n);
    y->resize(targets.rows(), n);
    for (long r = 0; r < n; ++r) {
      x->col(r) = inputs.col(rows[r]);
      y->col(r) = targets.col(rows[r]);
    }
  }
  Eigen::MatrixXf inputs, targets;
};

// A group is two first-network rows (a, 1) and (b, 1); the second network's row is (a, b).
class PairColumns final : public MlpPairDataset {
 public:
  int first_input_size() const override { return 2; }
  int second_input_size() const override { return 2; }
  int group_size() const override { return 2; }
  void Gather(const long* rows, long n, Eigen::MatrixXf* first,
              Eigen::MatrixXf* second) const override {
    first->resize(2, 2 * n);
    second->resize(2, n);
    for (long r = 0; r < n; ++r) {
      const Eigen::Vector2f ab = values.col(rows[r]);
      first->col(2 * r) << ab[0], 1.0f;
      first->col(2 * r + 1) << ab[1], 1.0f;
      second->col(r) = ab;
    }
  }
  Eigen::MatrixXf values;  // 2 x groups
};

std::vector<long> Range(long n) {
  std::vector<long> rows(n);
  for (long i = 0; i < n; ++i) rows[i] = i;
  return rows;
}

// The first network f(x, s) is supervised only at s = 0 (target sin 2x); the second, h(a, b),
// is supervised everywhere with (cos a, cos b). On the consistency rows (s = 1) f has no target
// of its own: only the consistency term can tell it f(x, 1) = cos x.
struct Fixture {
  ColumnsDataset first_data, second_data;
  PairColumns pair;
  Mlp first, second;

  explicit Fixture(uint64_t seed) {
    const int n = 400;
    const Eigen::RowVectorXf x = Eigen::RowVectorXf::LinSpaced(n, -1.5f, 1.5f);
    first_data.inputs.resize(2, n);
    first_data.inputs.row(0) = x;
    first_data.inputs.row(1).setZero();
    first_data.targets = (2.0f * x).array().sin().matrix();
    std::srand(static_cast<unsigned>(seed));
    pair.values = Eigen::MatrixXf::Random(2, n) * 1.5f;
    second_data.inputs = pair.values;
    second_data.targets = pair.values.array().cos().matrix();

    MlpShape f_shape;
    f_shape.input_size = 2;
    f_shape.hidden_units = 32;
    f_shape.output_size = 1;
    MlpShape h_shape = f_shape;
    h_shape.output_size = 2;
    first = Mlp::Create(f_shape, seed).value();
    second = Mlp::Create(h_shape, seed + 1).value();
    MlpTrainOptions train;
    train.epochs = 150;
    train.batch_size = 100;
    train.learning_rate = 3e-3;
    train.show_progress = false;
    train.seed = seed;
    EXPECT_TRUE(TrainMlp(first_data, Range(n), {}, train, &first, nullptr).ok());
    EXPECT_TRUE(TrainMlp(second_data, Range(n), {}, train, &second, nullptr).ok());
  }

  // RMS of f(x, 1) - cos x over a grid: what only the consistency term teaches.
  double UnsupervisedError() const {
    Eigen::MatrixXf grid(2, 61);
    grid.row(0) = Eigen::RowVectorXf::LinSpaced(61, -1.4f, 1.4f);
    grid.row(1).setOnes();
    const Eigen::MatrixXf predicted = first.Predict(grid);
    return std::sqrt((predicted.array() - grid.row(0).array().cos()).square().mean());
  }
  // RMS of f(x, 0) - sin 2x over the supervised rows.
  double SupervisedError() const {
    return std::sqrt(
        (first.Predict(first_data.inputs) - first_data.targets).array().square().mean());
  }

  static std::vector<long> PairValidationRows() { return {300, 301, 302, 303, 350, 399}; }

  // The validation objective keep_least_validation minimises, computed from the networks as they
  // are: f's and h's mean squared errors over their validation rows (all 400 each) plus
  // pair_weight times the mean squared difference of f's and h's outputs over the pair
  // validation rows.
  double ValidationObjective(double pair_weight) const {
    const double first_loss =
        (first.Predict(first_data.inputs) - first_data.targets).array().square().mean();
    const double second_loss =
        (second.Predict(second_data.inputs) - second_data.targets).array().square().mean();
    Eigen::MatrixXf first_inputs, second_inputs;
    const std::vector<long> rows = PairValidationRows();
    pair.Gather(rows.data(), static_cast<long>(rows.size()), &first_inputs, &second_inputs);
    const Eigen::MatrixXf f_out = first.Predict(first_inputs);    // 1 x 2n: (a, b) per row
    const Eigen::MatrixXf h_out = second.Predict(second_inputs);  // 2 x n
    const Eigen::Map<const Eigen::MatrixXf> h_by_member(h_out.data(), 1, h_out.size());
    const double pair_loss = (f_out - h_by_member).array().square().mean();
    return first_loss + second_loss + pair_weight * pair_loss;
  }

  MlpPairTrainSummary Train(double pair_weight, bool pair_trains_second,
                            bool keep_least_validation = false, long steps_per_report = 300,
                            double learning_rate = 1e-3) {
    MlpPairTrainOptions options;
    options.steps = 900;
    options.steps_per_report = steps_per_report;
    options.keep_least_validation = keep_least_validation;
    options.learning_rate = learning_rate;
    options.first_batch = 100;
    options.second_batch = 100;
    options.pair_batch = 50;
    options.pair_weight = pair_weight;
    options.pair_trains_second = pair_trains_second;
    options.show_progress = false;
    MlpPairTrainSummary summary;
    const Status status =
        TrainMlpPair(first_data, Range(400), Range(400), second_data, Range(400), Range(400), pair,
                     Range(300), PairValidationRows(), options, &first, &second, &summary);
    EXPECT_TRUE(status.ok()) << status.message();
    return summary;
  }
};

TEST(MlpPair, ConsistencyTeachesTheFirstNetworkWhereOnlyTheSecondIsSupervised) {
  for (uint64_t seed : {1u, 2u}) {
    SCOPED_TRACE(seed);
    Fixture with(seed), without(seed);
    const double before = with.UnsupervisedError();
    EXPECT_EQ(before, without.UnsupervisedError());  // same seeds, same networks
    const MlpPairTrainSummary summary = with.Train(1.0, true);
    without.Train(0.0, true);
    // Without the term nothing ties f(x, 1) to cos x; with it f learns it from h.
    EXPECT_GT(without.UnsupervisedError(), 0.5);  // 0.84, 1.04 for seeds 1, 2
    EXPECT_LT(with.UnsupervisedError(), 0.3 * without.UnsupervisedError());
    EXPECT_LT(with.UnsupervisedError(), 0.05);  // 0.009, 0.005
    // ... without giving up its own supervision.
    EXPECT_LT(with.SupervisedError(), 0.03);  // 0.012 for both
    ASSERT_EQ(summary.pair_loss.size(), 3u);
    ASSERT_EQ(summary.first_validation_loss.size(), 3u);
    ASSERT_EQ(summary.second_validation_loss.size(), 3u);
    ASSERT_EQ(summary.pair_validation_loss.size(), 3u);
    EXPECT_LT(summary.pair_loss.back(), 0.25 * summary.pair_loss.front());
    EXPECT_EQ(summary.steps, 900);
  }
}

TEST(MlpPair, TheSecondNetworkCanBeKeptOutOfTheConsistencyTerm) {
  // With pair_trains_second false the second network sees only its own loss, so its parameters
  // do not depend on the consistency weight.
  Fixture a(3), b(3);
  a.Train(1.0, false);
  b.Train(5.0, false);
  EXPECT_EQ(a.second.FlatParameters(), b.second.FlatParameters());
  EXPECT_NE(a.first.FlatParameters(), b.first.FlatParameters());
  Fixture c(3);
  c.Train(5.0, true);
  EXPECT_NE(c.second.FlatParameters(), b.second.FlatParameters());
}

TEST(MlpPair, KeepLeastValidationEndsWithTheBestReportsParameters) {
  // The same training twice (same seeds), once keeping the last report's parameters and once
  // the least validation objective's; a learning rate ten times the fine-tuning one makes the
  // objective rise and fall between reports.
  Fixture kept(5), last(5);
  const MlpPairTrainSummary with = kept.Train(1.0, true, true, 50, 1e-2);
  const MlpPairTrainSummary without = last.Train(1.0, true, false, 50, 1e-2);
  ASSERT_EQ(with.first_validation_loss.size(), 18u);
  ASSERT_EQ(with.second_validation_loss.size(), 18u);
  ASSERT_EQ(with.pair_validation_loss.size(), 18u);
  // Keeping changes nothing in the training itself.
  EXPECT_EQ(with.first_validation_loss, without.first_validation_loss);
  EXPECT_EQ(with.second_validation_loss, without.second_validation_loss);
  EXPECT_EQ(with.pair_validation_loss, without.pair_validation_loss);
  std::vector<double> objective;
  for (size_t r = 0; r < with.first_validation_loss.size(); ++r) {
    objective.push_back(with.first_validation_loss[r] + with.second_validation_loss[r] +
                        with.pair_validation_loss[r]);
  }
  const long best =
      static_cast<long>(std::min_element(objective.begin(), objective.end()) - objective.begin());
  EXPECT_EQ(with.kept_report, best);
  EXPECT_EQ(without.kept_report, 17);
  // The networks are those of the kept report: their objective, computed afresh, is the one
  // recorded for it (float networks: to 1e-4 relative), and the last report's without keeping.
  EXPECT_NEAR(kept.ValidationObjective(1.0), objective[best], 1e-4 * objective[best]);
  EXPECT_NEAR(last.ValidationObjective(1.0), objective.back(), 1e-4 * objective.back());
  // The fixture exercises the keeping: here the objective (both networks' validation losses and
  // the pair's) is least at report 16 of 18 (1.14e-4, then 1.19e-4 and 1.31e-4), so the kept
  // networks are not the last ones.
  ASSERT_LT(best + 1, static_cast<long>(objective.size()));
  EXPECT_NE(kept.first.FlatParameters(), last.first.FlatParameters());
  EXPECT_LT(kept.ValidationObjective(1.0), last.ValidationObjective(1.0));
}

TEST(MlpPair, RefusesMismatchedSizesAndEmptyRows) {
  Fixture fixture(4);
  MlpPairTrainOptions options;
  options.show_progress = false;
  options.steps = 1;
  // The second network's dataset where the first's belongs.
  Status status =
      TrainMlpPair(fixture.second_data, Range(10), {}, fixture.second_data, Range(10), {},
                   fixture.pair, Range(10), {}, options, &fixture.first, &fixture.second, nullptr);
  EXPECT_FALSE(status.ok());
  EXPECT_THAT(status.message(), HasSubstr("first outputs"));
  status = TrainMlpPair(fixture.first_data, Range(10), {}, fixture.second_data, Range(10), {},
                        fixture.pair, {}, {}, options, &fixture.first, &fixture.second, nullptr);
  EXPECT_THAT(status.message(), HasSubstr("no consistency rows"));
  options.pair_weight = -1;
  status =
      TrainMlpPair(fixture.first_data, Range(10), {}, fixture.second_data, Range(10), {},
                   fixture.pair, Range(10), {}, options, &fixture.first, &fixture.second, nullptr);
  EXPECT_THAT(status.message(), HasSubstr("pair_weight"));
  // Early stopping without validation rows to stop on.
  options.pair_weight = 1;
  options.keep_least_validation = true;
  status =
      TrainMlpPair(fixture.first_data, Range(10), {}, fixture.second_data, Range(10), {},
                   fixture.pair, Range(10), {}, options, &fixture.first, &fixture.second, nullptr);
  EXPECT_THAT(status.message(), HasSubstr("keep_least_validation needs validation rows"));
}

}  // namespace
}  // namespace facedyn::learn
