// The shared normalised MLP and its trainer (learn/mlp.h).

#include "learn/mlp.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstring>
#include <random>
#include <thread>

#include "tests/support/test_support.h"

namespace facedyn::learn {
namespace {

using ::testing::HasSubstr;

// Rows are the columns of fixed input and target matrices (filled by the derived class).
class ColumnsDataset : public MlpDataset {
 public:
  int input_size() const override { return static_cast<int>(inputs_.rows()); }
  int output_size() const override { return static_cast<int>(targets_.rows()); }
  void Gather(const long* rows, long n, Eigen::MatrixXf* inputs,
              Eigen::MatrixXf* targets) const override {
    inputs->resize(inputs_.rows(), n);
    targets->resize(targets_.rows(), n);
    for (long r = 0; r < n; ++r) {
      inputs->col(r) = inputs_.col(rows[r]);
      targets->col(r) = targets_.col(rows[r]);
    }
  }
  Eigen::MatrixXf inputs_, targets_;
};

// y = A x + b with a fixed A, b: rows are columns of a fixed random input matrix.
class LinearDataset final : public ColumnsDataset {
 public:
  explicit LinearDataset(int rows) {
    inputs_ = Eigen::MatrixXf::Random(4, rows) * 10.0f;
    a_ = Eigen::MatrixXf::Random(2, 4);
    b_ = Eigen::Vector2f(100.0f, -50.0f);
    targets_ = (a_ * inputs_).colwise() + b_;
  }
  Eigen::MatrixXf a_;
  Eigen::Vector2f b_;
};

MlpShape SmallShape() {
  MlpShape shape;
  shape.input_size = 4;
  shape.hidden_units = 32;
  shape.output_size = 2;
  return shape;
}

TEST(MlpShape, CheckAndMultiplyAdds) {
  MlpShape shape = SmallShape();
  EXPECT_TRUE(shape.Check().ok());
  EXPECT_DOUBLE_EQ(shape.ForwardMultiplyAdds(), 4 * 32 + 32 * 32 + 32 * 2);
  shape.hidden_layers = 0;
  EXPECT_THAT(shape.Check().message(), HasSubstr("hidden_layers"));
}

TEST(TrainMlp, FitsALinearMapInRawUnits) {
  const LinearDataset data(2000);
  std::vector<long> train, validation;
  for (long r = 0; r < 2000; ++r) (r % 10 == 0 ? validation : train).push_back(r);
  Mlp model = Mlp::Create(SmallShape(), 3).value();
  MlpTrainOptions options;
  options.epochs = 60;
  options.batch_size = 64;
  options.show_progress = false;
  MlpTrainSummary summary;
  ASSERT_TRUE(TrainMlp(data, train, validation, options, &model, &summary).ok());
  EXPECT_EQ(summary.training_rows, 1800);
  EXPECT_EQ(summary.validation_rows, 200);
  ASSERT_EQ(summary.train_loss.size(), 60u);
  // The loss is in the outputs' units squared: 1% of their mean variance.
  const Eigen::MatrixXf centred = data.targets_.colwise() - data.targets_.rowwise().mean();
  const double mean_variance = centred.squaredNorm() / centred.size();
  EXPECT_LT(summary.validation_loss.back(), 0.01 * mean_variance);
  // Predictions come back in raw units (the normalisation is inside the model).
  Eigen::MatrixXf inputs(4, 200);
  for (int r = 0; r < 200; ++r) inputs.col(r) = data.inputs_.col(validation[r]);
  const Eigen::MatrixXf predicted = model.Predict(inputs);
  const Eigen::MatrixXf truth = (data.a_ * inputs).colwise() + data.b_;
  const double rms = std::sqrt((predicted - truth).squaredNorm() / predicted.size());
  const double spread =
      std::sqrt((truth.colwise() - truth.rowwise().mean()).squaredNorm() / truth.size());
  EXPECT_LT(rms, 0.1 * spread) << "rms " << rms << " spread " << spread;
}

// Two outputs 1000x apart in scale, more than a tiny network can fit both of: y0 = 1000
// sin(x0), y1 = sin(x1).
class TwoScaleDataset final : public MlpDataset {
 public:
  explicit TwoScaleDataset(int rows) {
    inputs_ = Eigen::MatrixXf::Random(2, rows) * 3.0f;
    targets_.resize(2, rows);
    for (int r = 0; r < rows; ++r) {
      targets_(0, r) = 1000.0f * std::sin(inputs_(0, r));
      targets_(1, r) = std::sin(inputs_(1, r));
    }
  }
  int input_size() const override { return 2; }
  int output_size() const override { return 2; }
  void Gather(const long* rows, long n, Eigen::MatrixXf* inputs,
              Eigen::MatrixXf* targets) const override {
    inputs->resize(2, n);
    targets->resize(2, n);
    for (long r = 0; r < n; ++r) {
      inputs->col(r) = inputs_.col(rows[r]);
      targets->col(r) = targets_.col(rows[r]);
    }
  }
  Eigen::MatrixXf inputs_, targets_;
};

// Relative RMS error of each output after training with or without the output-unit loss, and
// the reported final validation loss next to the mean squared raw error computed here.
struct TwoScaleFit {
  double relative_rms[2] = {0, 0};
  double reported_loss = 0, measured_mse = 0;
};
TwoScaleFit FitTwoScales(bool loss_in_output_units) {
  const TwoScaleDataset data(3000);
  std::vector<long> train, validation;
  for (long r = 0; r < 3000; ++r) (r % 5 == 0 ? validation : train).push_back(r);
  MlpShape shape;
  shape.input_size = 2;
  shape.hidden_units = 3;
  shape.output_size = 2;
  Mlp model = Mlp::Create(shape, 5).value();
  MlpTrainOptions options;
  options.epochs = 40;
  options.batch_size = 64;
  options.show_progress = false;
  options.loss_in_output_units = loss_in_output_units;
  MlpTrainSummary summary;
  EXPECT_TRUE(TrainMlp(data, train, validation, options, &model, &summary).ok());
  Eigen::MatrixXf inputs(2, validation.size()), truth(2, validation.size());
  for (size_t r = 0; r < validation.size(); ++r) {
    inputs.col(r) = data.inputs_.col(validation[r]);
    truth.col(r) = data.targets_.col(validation[r]);
  }
  const Eigen::MatrixXf error = model.Predict(inputs) - truth;
  TwoScaleFit fit;
  for (int d = 0; d < 2; ++d) {
    fit.relative_rms[d] = std::sqrt(error.row(d).squaredNorm() / truth.row(d).squaredNorm());
  }
  fit.reported_loss = summary.validation_loss.back();
  fit.measured_mse = error.squaredNorm() / error.size();
  return fit;
}

TEST(TrainMlp, LossInOutputUnitsWeighsTheLargeOutputAndIsReportedInUnitsSquared) {
  const TwoScaleFit units = FitTwoScales(true);
  const TwoScaleFit normalised = FitTwoScales(false);
  // Reported in units^2: the mean squared raw error over both outputs, computed independently.
  EXPECT_NEAR(units.reported_loss, units.measured_mse, 1e-3 * units.measured_mse);
  // The squared error in units is dominated by y0, so that weighting fits y0 better and y1
  // worse than the normalised loss, which weighs both alike.
  EXPECT_LT(units.relative_rms[0], normalised.relative_rms[0]);
  EXPECT_GT(units.relative_rms[1], normalised.relative_rms[1]);
}

TEST(MlpTrainOptions, CheckNamesTheField) {
  MlpTrainOptions options;
  EXPECT_TRUE(options.Check().ok());
  options.final_learning_rate_fraction = 0;
  EXPECT_THAT(options.Check().message(), HasSubstr("final_learning_rate_fraction"));
  options = MlpTrainOptions();
  options.batch_size = 0;
  EXPECT_THAT(options.Check().message(), HasSubstr("batch_size"));
}

// The small model (seed 9) trained on every row of `data`, no validation; a failed training
// fails the calling test. (Each test makes its own dataset: LinearDataset draws from Eigen's
// global random state.)
std::vector<long> AllRows(const ColumnsDataset& data) {
  std::vector<long> rows(data.inputs_.cols());
  for (long r = 0; r < static_cast<long>(rows.size()); ++r) rows[r] = r;
  return rows;
}

Mlp TrainSmallOnAllRows(const LinearDataset& data, const MlpTrainOptions& options) {
  Mlp model = Mlp::Create(SmallShape(), 9).value();
  EXPECT_TRUE(TrainMlp(data, AllRows(data), {}, options, &model, nullptr).ok());
  return model;
}

MlpTrainOptions QuietOptions(int epochs) {
  MlpTrainOptions options;
  options.epochs = epochs;
  options.batch_size = 50;
  options.show_progress = false;
  return options;
}

TEST(TrainMlp, DecayingLearningRateIsDeterministicAndDiffersFromConstant) {
  const LinearDataset data(500);
  MlpTrainOptions options = QuietOptions(5);
  auto train = [&](double fraction) {
    options.final_learning_rate_fraction = fraction;
    return TrainSmallOnAllRows(data, options).FlatParameters();
  };
  const std::vector<float> decayed = train(0.01);
  EXPECT_EQ(train(0.01), decayed);
  EXPECT_NE(train(1.0), decayed);
}

// A step budget (paper Fig. 5's equal budgets): exactly that many Adam steps whatever the rows,
// the last epoch cut short; a budget of whole epochs trains bitwise as `epochs` does.
TEST(TrainMlp, OptimizerStepBudgetIsExactWhateverTheRows) {
  const LinearDataset data(500);  // 10 batches of 50 per epoch
  MlpTrainOptions options = QuietOptions(3);
  MlpTrainSummary summary;
  Mlp by_epochs = Mlp::Create(SmallShape(), 9).value();
  ASSERT_TRUE(TrainMlp(data, AllRows(data), {}, options, &by_epochs, &summary).ok());
  EXPECT_EQ(summary.optimizer_steps, 30);
  EXPECT_EQ(summary.epochs, 3);

  options.optimizer_steps = 30;
  options.epochs = 7;  // ignored under a budget
  EXPECT_EQ(TrainSmallOnAllRows(data, options).FlatParameters(), by_epochs.FlatParameters());

  // Fewer rows, the same budget: more epochs, the last one partial.
  std::vector<long> fewer = AllRows(data);
  fewer.resize(120);  // 3 batches per epoch (50, 50, 20)
  options.optimizer_steps = 31;
  Mlp on_fewer = Mlp::Create(SmallShape(), 9).value();
  ASSERT_TRUE(TrainMlp(data, fewer, {}, options, &on_fewer, &summary).ok());
  EXPECT_EQ(summary.optimizer_steps, 31);
  EXPECT_EQ(summary.epochs, 11);  // ceil(31 / 3)
  ASSERT_EQ(summary.train_loss.size(), 11u);
  EXPECT_TRUE(std::isfinite(summary.train_loss.back()));

  options.optimizer_steps = -1;
  EXPECT_THAT(options.Check().message(), HasSubstr("optimizer_steps"));
}

TEST(MlpTrainOptions, RegularisersDefaultToNoneAndAreChecked) {
  MlpTrainOptions options;
  EXPECT_EQ(options.weight_decay, 0.0);
  EXPECT_EQ(options.input_noise_std, 0.0);
  options.weight_decay = -1e-3;
  EXPECT_THAT(options.Check().message(), HasSubstr("weight_decay"));
  options = MlpTrainOptions();
  options.input_noise_std = -0.1;
  EXPECT_THAT(options.Check().message(), HasSubstr("input_noise_std"));
}

// Sum of squares of the weights and biases (FlatParameters lists them before the buffers).
double SquaredParameterNorm(const Mlp& model, const MlpShape& shape) {
  const std::vector<float> flat = model.FlatParameters();
  const size_t buffers = 2 * shape.input_size + 2 * shape.output_size;
  double sum = 0.0;
  for (size_t k = 0; k + buffers < flat.size(); ++k) sum += double(flat[k]) * flat[k];
  return sum;
}

TEST(TrainMlp, WeightDecayShrinksTheWeightsAndZeroIsPlainAdamBitwise) {
  const LinearDataset data(500);
  auto train = [&](const MlpTrainOptions& options) { return TrainSmallOnAllRows(data, options); };
  const MlpTrainOptions options = QuietOptions(20);
  const Mlp plain = train(options);
  // Explicit zeros take the default path: the same parameters to the bit.
  MlpTrainOptions zeros = options;
  zeros.weight_decay = 0.0;
  zeros.input_noise_std = 0.0;
  EXPECT_EQ(train(zeros).FlatParameters(), plain.FlatParameters());
  // A strong decay (lr * decay * steps = 1e-3 * 2 * 200 = 0.4) pulls the weights towards zero.
  MlpTrainOptions decayed = options;
  decayed.weight_decay = 2.0;
  const Mlp shrunk = train(decayed);
  EXPECT_LT(SquaredParameterNorm(shrunk, SmallShape()),
            0.9 * SquaredParameterNorm(plain, SmallShape()));
  EXPECT_EQ(train(decayed).FlatParameters(), shrunk.FlatParameters());  // deterministic
}

TEST(TrainMlp, InputNoiseIsDeterministicAndChangesTheFit) {
  const LinearDataset data(500);
  MlpTrainOptions options = QuietOptions(5);
  auto train = [&](double noise) {
    options.input_noise_std = noise;
    return TrainSmallOnAllRows(data, options).FlatParameters();
  };
  const std::vector<float> noisy = train(0.1);
  EXPECT_EQ(train(0.1), noisy);
  EXPECT_NE(train(0.0), noisy);
}

TEST(Mlp, LinearSkipStartsAsThePlainNetworkAndRoundTrips) {
  MlpShape shape = SmallShape();
  shape.linear_skip = true;
  EXPECT_DOUBLE_EQ(shape.ForwardMultiplyAdds(), SmallShape().ForwardMultiplyAdds() + 4 * 2);
  const Mlp plain = Mlp::Create(SmallShape(), 5).value();
  Mlp skip = Mlp::Create(shape, 5).value();
  EXPECT_EQ(skip.FlatParameters().size(), plain.FlatParameters().size() + 4 * 2);
  const Eigen::MatrixXf inputs = Eigen::MatrixXf::Random(4, 16) * 10.0f;
  // Zero-initialised skip, the same draws for fc1..fc3: the same function at the start.
  EXPECT_EQ(skip.Predict(inputs), plain.Predict(inputs));

  const LinearDataset data(500);
  ASSERT_TRUE(TrainMlp(data, AllRows(data), {}, QuietOptions(3), &skip, nullptr).ok());
  testing::TempDir dir;
  ASSERT_TRUE(skip.Save(dir.Join("m.pt"), "removal", Json::object()).ok());
  Json config;
  const auto loaded = Mlp::Load(dir.Join("m.pt"), "removal", &config);
  ASSERT_TRUE(loaded.ok()) << loaded.status().message();
  EXPECT_TRUE(loaded->shape().linear_skip);
  EXPECT_EQ(config["mlp"]["linear_skip"], true);
  EXPECT_EQ(loaded->Predict(inputs), skip.Predict(inputs));
  EXPECT_NE(skip.Predict(inputs), plain.Predict(inputs));  // training changed it
}

TEST(Mlp, CloneIsADeepCopy) {
  MlpShape shape = SmallShape();
  shape.linear_skip = true;
  Mlp original = Mlp::Create(shape, 7).value();
  const LinearDataset data(500);
  ASSERT_TRUE(TrainMlp(data, AllRows(data), {}, QuietOptions(2), &original, nullptr).ok());
  const Eigen::MatrixXf inputs = Eigen::MatrixXf::Random(4, 16) * 10.0f;
  const Eigen::MatrixXf before = original.Predict(inputs);
  Mlp copy = original.Clone();
  EXPECT_EQ(copy.FlatParameters(), original.FlatParameters());  // normalisation included
  EXPECT_EQ(copy.Predict(inputs), before);
  EXPECT_TRUE(copy.shape().linear_skip);
  // Training the copy leaves the original as it was.
  ASSERT_TRUE(TrainMlp(data, AllRows(data), {}, QuietOptions(2), &copy, nullptr).ok());
  EXPECT_NE(copy.Predict(inputs), before);
  EXPECT_EQ(original.Predict(inputs), before);
}

// y = A x + 3 e^2 for three main inputs x and one extra input e (which joins hidden layer 2).
class ExtraInputDataset final : public ColumnsDataset {
 public:
  // Its own generator: the data must not depend on which tests ran before.
  explicit ExtraInputDataset(int rows) {
    std::mt19937 rng(42);
    std::uniform_real_distribution<float> uniform(-1.0f, 1.0f);
    inputs_ = Eigen::MatrixXf::NullaryExpr(4, rows, [&] { return 2.0f * uniform(rng); });
    const Eigen::MatrixXf a = Eigen::MatrixXf::NullaryExpr(2, 3, [&] { return uniform(rng); });
    targets_ = a * inputs_.topRows(3);
    targets_.row(0) += 3.0f * inputs_.row(3).cwiseAbs2();
  }
};

// The FDLS options together: residual hidden layers, dropout, the last input joining layer 2.
MlpShape FdlsShape() {
  MlpShape shape = SmallShape();
  shape.hidden_layers = 3;
  shape.residual = true;
  shape.dropout = 0.1;
  shape.extra_input_size = 1;
  shape.extra_input_layer = 2;
  return shape;
}

TEST(MlpShape, FdlsOptionsAreCheckedByName) {
  EXPECT_TRUE(FdlsShape().Check().ok());
  MlpShape shape = FdlsShape();
  shape.dropout = 1.0;
  EXPECT_THAT(shape.Check().message(), HasSubstr("dropout"));
  shape = FdlsShape();
  shape.extra_input_layer = 1;
  EXPECT_THAT(shape.Check().message(), HasSubstr("extra_input_layer"));
  shape.extra_input_layer = 4;  // past the last hidden layer
  EXPECT_THAT(shape.Check().message(), HasSubstr("extra_input_layer"));
  shape = FdlsShape();
  shape.extra_input_size = 4;  // every input
  EXPECT_THAT(shape.Check().message(), HasSubstr("extra_input_size"));
  shape = SmallShape();
  shape.extra_input_layer = 2;
  EXPECT_THAT(shape.Check().message(), HasSubstr("without extra inputs"));
}

TEST(Mlp, TheExtraInputJoinsItsLayerAndTheOutputDependsOnIt) {
  const Mlp model = Mlp::Create(FdlsShape(), 3).value();
  // fc1 sees the 3 main inputs, fc2 its 32 activations plus the extra one, fc3, the output.
  const size_t parameters = (3 * 32 + 32) + (33 * 32 + 32) + (32 * 32 + 32) + (32 * 2 + 2);
  const size_t buffers = 4 + 4 + 2 + 2;
  EXPECT_EQ(model.FlatParameters().size(), parameters + buffers);
  Eigen::MatrixXf inputs = Eigen::MatrixXf::Random(4, 8);
  const Eigen::MatrixXf base = model.Predict(inputs);
  EXPECT_EQ(model.Predict(inputs), base) << "dropout acted while predicting";
  inputs.row(3).array() += 1.0f;
  EXPECT_GT((model.Predict(inputs) - base).cwiseAbs().maxCoeff(), 1e-4f);
}

TEST(TrainMlp, ResidualDropoutAndExtraInputFitDeterministicallyAndRoundTrip) {
  const ExtraInputDataset data(2000);
  std::vector<long> rows = AllRows(data);
  const std::vector<long> validation(rows.begin(), rows.begin() + 400);
  const std::vector<long> train(rows.begin() + 400, rows.end());
  MlpTrainOptions options = QuietOptions(80);
  options.batch_size = 200;
  Mlp first = Mlp::Create(FdlsShape(), 11).value();
  Mlp second = Mlp::Create(FdlsShape(), 11).value();
  MlpTrainSummary summary, again;
  ASSERT_TRUE(TrainMlp(data, train, validation, options, &first, &summary).ok());
  ASSERT_TRUE(TrainMlp(data, train, validation, options, &second, &again).ok());
  EXPECT_EQ(first.FlatParameters(), second.FlatParameters()) << "dropout is not reproducible";
  // It learns, the extra input's square included: a linear map of the inputs cannot fit 3 e^2,
  // whose variance is most of output 0's.
  EXPECT_LT(summary.validation_loss.back(), 0.1 * summary.validation_loss.front());
  // Validation runs without dropout, training with it: the clean loss is the lower one.
  EXPECT_LT(summary.validation_loss.back(), summary.train_loss.back());
  testing::TempDir dir;
  ASSERT_TRUE(first.Save(dir.Join("m.pt"), "solve", Json::object()).ok());
  Json config;
  const auto loaded = Mlp::Load(dir.Join("m.pt"), "solve", &config);
  ASSERT_TRUE(loaded.ok()) << loaded.status().message();
  EXPECT_EQ(config["mlp"]["residual"], true);
  EXPECT_EQ(config["mlp"]["extra_input_layer"], 2);
  EXPECT_DOUBLE_EQ(config["mlp"]["dropout"].get<double>(), 0.1);
  const Eigen::MatrixXf inputs = data.inputs_.leftCols(16);
  EXPECT_EQ(loaded->Predict(inputs), first.Predict(inputs));
}

// Independent networks created and trained on threads at once (as the demo trains F beside
// subject B's networks) come out bitwise as when trained one after the other: creation seeds
// LibTorch's global generator under a lock, dropout and input noise use the trainer's own.
TEST(TrainMlp, NetworksTrainedOnThreadsAtOnceMatchTheSequentialOnes) {
  const ExtraInputDataset data(600);
  const std::vector<long> rows = AllRows(data);
  MlpTrainOptions options = QuietOptions(4);
  options.batch_size = 100;
  options.input_noise_std = 0.05;
  constexpr int kNetworks = 4;
  auto create_and_train = [&](int k) {
    Mlp model = Mlp::Create(FdlsShape(), 100 + k).value();
    MlpTrainOptions own = options;
    own.seed = 200 + k;
    EXPECT_TRUE(TrainMlp(data, rows, {}, own, &model, nullptr).ok());
    return model.FlatParameters();
  };
  std::vector<std::vector<float>> sequential;
  for (int k = 0; k < kNetworks; ++k) sequential.push_back(create_and_train(k));
  for (int round = 0; round < 3; ++round) {
    std::vector<std::vector<float>> concurrent(kNetworks);
    std::atomic<int> ready{0};
    std::vector<std::thread> threads;
    for (int k = 0; k < kNetworks; ++k) {
      threads.emplace_back([&, k] {
        ++ready;
        while (ready.load() < kNetworks) std::this_thread::yield();  // start together
        concurrent[k] = create_and_train(k);
      });
    }
    for (std::thread& thread : threads) thread.join();
    for (int k = 0; k < kNetworks; ++k) {
      EXPECT_EQ(concurrent[k], sequential[k]) << "network " << k << ", round " << round;
    }
  }
}

TEST(TrainMlp, RefusesMismatchedSizesAndNoRows) {
  const LinearDataset data(10);
  MlpShape shape = SmallShape();
  shape.input_size = 5;
  Mlp model = Mlp::Create(shape, 1).value();
  MlpTrainOptions options;
  options.show_progress = false;
  EXPECT_THAT(TrainMlp(data, {0, 1}, {}, options, &model, nullptr).message(), HasSubstr("4 -> 2"));
  Mlp small = Mlp::Create(SmallShape(), 1).value();
  EXPECT_EQ(TrainMlp(data, {}, {}, options, &small, nullptr).code(),
            StatusCode::kFailedPrecondition);
}

TEST(Mlp, SaveLoadRoundTripAndKindCheck) {
  const Mlp model = Mlp::Create(SmallShape(), 5).value();
  testing::TempDir dir;
  ASSERT_TRUE(model.Save(dir.Join("m.pt"), "removal", Json{{"note", "x"}}).ok());
  Json config;
  const auto loaded = Mlp::Load(dir.Join("m.pt"), "removal", &config);
  ASSERT_TRUE(loaded.ok()) << loaded.status().message();
  EXPECT_EQ(loaded->FlatParameters(), model.FlatParameters());
  EXPECT_EQ(config["note"], "x");
  EXPECT_EQ(config["mlp"]["hidden_units"], 32);
  const auto wrong = Mlp::Load(dir.Join("m.pt"), "synthesis", &config);
  EXPECT_EQ(wrong.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(wrong.status().message(),
              HasSubstr("is a removal model, expected a synthesis model"));
}

TEST(Mlp, AttachmentsRoundTripBitwise) {
  const Mlp model = Mlp::Create(SmallShape(), 5).value();
  testing::TempDir dir;
  MlpAttachments attachments;
  attachments["w"] = Eigen::MatrixXf::Random(7, 3);
  attachments["empty"] = Eigen::MatrixXf(0, 4);
  ASSERT_TRUE(model.Save(dir.Join("m.pt"), "removal", Json::object(), attachments).ok());
  Json config;
  MlpAttachments loaded;
  ASSERT_TRUE(Mlp::Load(dir.Join("m.pt"), "removal", &config, &loaded).ok());
  ASSERT_EQ(loaded.size(), 2u);
  EXPECT_EQ(loaded.at("w"), attachments.at("w"));
  EXPECT_EQ(loaded.at("empty").rows(), 0);
  EXPECT_EQ(loaded.at("empty").cols(), 4);
  // A file without attachments loads with none.
  ASSERT_TRUE(model.Save(dir.Join("plain.pt"), "removal", Json::object()).ok());
  ASSERT_TRUE(Mlp::Load(dir.Join("plain.pt"), "removal", &config, &loaded).ok());
  EXPECT_TRUE(loaded.empty());
}

TEST(MeasureGemm, GivesAPositiveRate) {
  const double rate = MeasureGemmMultiplyAddsPerSecond(64, 64, 64, 0.0);
  EXPECT_GT(rate, 1e6);  // any machine this runs on does more than a million per second
}

}  // namespace
}  // namespace facedyn::learn
