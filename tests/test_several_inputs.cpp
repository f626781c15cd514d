// Several measured inputs (MISO): each submodel names the input that drives
// it. The configuration (model.inputs, a submodel's input), the record
// (the further input columns), the batch fit and the start from the data.
#include "config_support.hpp"

#include "modalwatch/io/records.hpp"

namespace {

// ---------------------------------------------------------------- configuration

const std::string kTwoInputs =
    "sample_rate_hz: 20\n"         // 1
    "model:\n"                     // 2
    "  loop: open\n"               // 3
    "  inputs: [u1, u2]\n"         // 4
    "  submodels:\n"               // 5
    "    - name: m1\n"             // 6
    "      wn: 2.0\n"              // 7
    "      zeta: 0.25\n"           // 8
    "      gain: 3.0\n"            // 9
    "    - name: m2\n"             // 10
    "      input: u2\n"            // 11
    "      frequency_hz: 1.0\n"    // 12
    "      zeta: 0.1\n"            // 13
    "      gain: 1.0\n";           // 14

TEST(SeveralInputsConfig, InputsAreNamedAndEachSubmodelIndexesOne) {
  const Config c = parse_config(kTwoInputs, "test.yaml");
  EXPECT_EQ(c.model.inputs, (std::vector<std::string>{"u1", "u2"}));
  EXPECT_EQ(c.model.n_inputs(), 2);
  ASSERT_EQ(c.model.submodels.size(), 2u);
  EXPECT_EQ(c.model.submodels[0].input, 0);  // absent: the first input
  EXPECT_EQ(c.model.submodels[1].input, 1);
}

TEST(SeveralInputsConfig, SingleInputConfigHasNoInputNames) {
  const Config c = parse_config(kBase, "test.yaml");
  EXPECT_TRUE(c.model.inputs.empty());
  EXPECT_EQ(c.model.n_inputs(), 1);
  for (const auto& s : c.model.submodels) EXPECT_EQ(s.input, 0);
  // The written file has no input keys at all: as before several inputs existed.
  const std::string yaml = modalwatch::config_to_yaml(c, c.model);
  EXPECT_EQ(yaml.find("input"), std::string::npos) << yaml;
}

TEST(SeveralInputsConfig, RoundTripsThroughTheWriter) {
  const Config c = parse_config(kTwoInputs, "test.yaml");
  const std::string yaml = modalwatch::config_to_yaml(c, c.model);
  EXPECT_CONTAINS(yaml, "inputs: [\"u1\", \"u2\"]");
  Config back = parse_config(yaml, "test.yaml");
  back.source = c.source;
  EXPECT_TRUE(back == c) << yaml;
  EXPECT_EQ(back.model.submodels[1].input, 1);
}

TEST(SeveralInputsConfig, ErrorsNameTheKeyAndLine) {
  EXPECT_EQ(parse_error(edit(kTwoInputs, "      input: u2", "      input: u3")),
            "test.yaml:11: key 'model.submodels[1].input': must be one of model.inputs (u1, u2) (got u3)");
  EXPECT_EQ(parse_error(edit(kBase, "      frequency_hz: 1.0", "      input: u2\n      frequency_hz: 1.0")),
            "test.yaml:12: key 'model.submodels[1].input': names an input, but model.inputs does not list the "
            "input columns (got u2)");
  EXPECT_EQ(parse_error(edit(kTwoInputs, "  inputs: [u1, u2]", "  inputs: [u1, u1]")),
            "test.yaml:4: key 'model.inputs[1]': duplicate input name (got u1)");
  EXPECT_EQ(parse_error(edit(kTwoInputs, "  inputs: [u1, u2]", "  inputs: []")),
            "test.yaml:4: key 'model.inputs': must list at least one input column (got [])");
  EXPECT_EQ(parse_error(edit(kTwoInputs, "  inputs: [u1, u2]", "  inputs: u1")),
            "test.yaml:4: key 'model.inputs': expected a list (got u1)");
  const std::string closed = edit(kTwoInputs, "  loop: open", "  loop: closed") +
                             "controller:\n  numerator: [1]\n  denominator: [1]\n";
  EXPECT_EQ(parse_error(closed), "test.yaml:4: key 'model.inputs': a closed loop has one input (the controller's u); "
                                 "several inputs need loop: open (got [u1, u2])");
}

// ---------------------------------------------------------------- record

class SeveralInputsRecord : public ::testing::Test {
 protected:
  std::string file(const std::string& name, const std::string& text) {
    const std::string p = (dir_ / name).string();
    std::ofstream(p) << text;
    return p;
  }
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("modalwatch_miso_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(SeveralInputsRecord, ReadsEveryNamedInputColumnAndSegmentKeepsThem) {
  modalwatch::RecordColumns cols;
  cols.u = "u1";
  cols.y = "y5";
  cols.further_u = {"u2"};
  const auto rec = modalwatch::read_record({file("m.csv", "t,u1,u2,y5\n0,1,10,5\n1,2,20,6\n2,3,30,7\n"), cols});
  ASSERT_EQ(rec.inputs(), 2);
  EXPECT_EQ(rec.u, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(rec.input(1), Eigen::Vector3d(10, 20, 30));
  EXPECT_EQ(rec.y(2), 7.0);
  const modalwatch::Record part = rec.segment(1, 2);
  ASSERT_EQ(part.inputs(), 2);
  EXPECT_EQ(part.input(1), Eigen::Vector2d(20, 30));
  EXPECT_EQ(part.input(0), Eigen::Vector2d(2, 3));
}

TEST_F(SeveralInputsRecord, AMissingInputColumnIsNamed) {
  modalwatch::RecordColumns cols;
  cols.further_u = {"u2"};
  try {
    modalwatch::read_record({file("m.csv", "t,u,y\n0,1,5\n1,2,6\n"), cols});
    FAIL() << "no error";
  } catch (const modalwatch::MissingColumnError& e) {
    EXPECT_EQ(e.column(), "u2");
  }
}

TEST_F(SeveralInputsRecord, OneInputByDefault) {
  const auto rec = modalwatch::read_record({file("s.csv", "t,u,y,u2\n0,1,5,9\n1,2,6,9\n")});
  EXPECT_EQ(rec.inputs(), 1);
  EXPECT_TRUE(rec.further_u.empty());
}

}  // namespace
