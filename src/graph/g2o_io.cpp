#include "hanzo/fusion/graph/g2o_io.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <fmt/format.h>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/core/yaml_value.hpp"
#include "hanzo/fusion/graph/pose_factors.hpp"

namespace hanzo::fusion::graph {
namespace {

Eigen::MatrixXd from_upper_triangle(const std::vector<double>& entries, int size) {
  Eigen::MatrixXd m(size, size);
  size_t k = 0;
  for (int i = 0; i < size; ++i) {
    for (int j = i; j < size; ++j) m(i, j) = m(j, i) = entries[k++];
  }
  return m;
}

Result<SO3> unit_rotation(double qx, double qy, double qz, double qw) {
  const Eigen::Quaterniond q(qw, qx, qy, qz);
  if (std::abs(q.norm() - 1.0) > 1e-3) return Error(fmt::format("quaternion norm {} is not 1", q.norm()));
  return SO3::from_quaternion_normalized(q);
}

// TORO's 3D rotations: R = Rz(yaw) Ry(pitch) Rx(roll), and back (pitch in [-pi/2, pi/2]).
SO3 from_roll_pitch_yaw(double roll, double pitch, double yaw) {
  return SO3::exp(Eigen::Vector3d(0.0, 0.0, yaw)) * SO3::exp(Eigen::Vector3d(0.0, pitch, 0.0)) * SO3::exp(Eigen::Vector3d(roll, 0.0, 0.0));
}
Eigen::Vector3d roll_pitch_yaw(const SO3& rotation) {
  const Eigen::Matrix3d R = rotation.matrix();
  return {std::atan2(R(2, 1), R(2, 2)), std::asin(std::clamp(-R(2, 0), -1.0, 1.0)), std::atan2(R(1, 0), R(0, 0))};
}

// TORO's 3D information is over (translation, roll, pitch, yaw), which to first order is the
// rotation vector, twice g2o's quaternion vector part: g2o information = D toro D, D = diag(1, 1, 1, 2, 2, 2).
Eigen::MatrixXd toro_to_g2o_scaling() {
  Eigen::MatrixXd D = Eigen::MatrixXd::Identity(6, 6);
  D.bottomRightCorner(3, 3) *= 2.0;
  return D;
}
// TORO's 2D information order (xx, xy, yy, tt, xt, yt) as a matrix over (x, y, theta).
Eigen::MatrixXd toro_2d_information(const double* i) {
  Eigen::Matrix3d m;
  m << i[0], i[1], i[4], i[1], i[2], i[5], i[4], i[5], i[3];
  return m;
}

Value compose(const Value& a, const Value& b) {
  if (const auto* a2 = std::get_if<SE2>(&a)) return *a2 * std::get<SE2>(b);
  return std::get<SE3>(a) * std::get<SE3>(b);
}
Value inverse(const Value& a) {
  if (const auto* a2 = std::get_if<SE2>(&a)) return a2->inverse();
  return std::get<SE3>(a).inverse();
}

// Makes an edge's information usable by the optimizer: positive definite. A matrix that is
// only semi-definite (a block of zeros) or slightly indefinite (rounding in the file) becomes
// the nearest positive definite one: its eigenvalues raised to at least 1e-6 of the largest
// (1e-6 when none is positive: next to no weight). Returns "" when it was usable as it is,
// else what was done.
std::string repair_information(Eigen::MatrixXd& information) {
  if (GaussianNoise::from_information(information)) return "";
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(0.5 * (information + information.transpose()));
  const Eigen::VectorXd& values = eigen.eigenvalues();  // ascending
  const double floor = values.maxCoeff() > 0 ? 1e-6 * values.maxCoeff() : 1e-6;
  information = eigen.eigenvectors() * values.cwiseMax(floor).asDiagonal() * eigen.eigenvectors().transpose();
  information = 0.5 * (information + information.transpose());
  return fmt::format("the information matrix is not positive definite (eigenvalues {:.3g} .. {:.3g}); "
                     "used the nearest positive definite one (eigenvalues >= {:.3g})",
                     values.minCoeff(), values.maxCoeff(), floor);
}

// Whether the translation and rotation blocks SE-Sync reads are positive definite.
bool se_sync_blocks_usable(const Eigen::MatrixXd& information, int dimension) {
  const int rotation = dimension == 3 ? 3 : 1;
  const Eigen::LLT<Eigen::MatrixXd> translation_block(information.topLeftCorner(dimension, dimension));
  const Eigen::LLT<Eigen::MatrixXd> rotation_block(information.bottomRightCorner(rotation, rotation));
  return translation_block.info() == Eigen::Success && rotation_block.info() == Eigen::Success;
}

// Sets edge.information from edge.file_information (repaired where needed) and records why.
void take_information(PoseGraphEdge& edge, PoseGraph& graph, const std::string& where) {
  edge.information = edge.file_information;
  if (std::string repaired = repair_information(edge.information); !repaired.empty()) {
    graph.warnings.push_back({"information_repaired", fmt::format("{}: {}", where, repaired)});
  }
  const int dimension = static_cast<int>(edge.file_information.rows()) == 6 ? 3 : 2;
  if (!se_sync_blocks_usable(edge.file_information, dimension)) {
    graph.warnings.push_back({"se_sync_weights_from_repaired",
                              fmt::format("{}: a translation or rotation block of the information matrix is not positive definite; "
                                          "SE-Sync's weights come from the repaired matrix",
                                          where)});
  }
}

}  // namespace

std::vector<WarningGroup> group_warnings(const std::vector<PoseGraphWarning>& warnings, std::size_t examples) {
  std::vector<WarningGroup> groups;
  for (const PoseGraphWarning& warning : warnings) {
    auto group = std::find_if(groups.begin(), groups.end(), [&](const WarningGroup& g) { return g.kind == warning.kind; });
    if (group == groups.end()) group = groups.insert(groups.end(), WarningGroup{warning.kind, 0, {}});
    ++group->count;
    if (group->first.size() < examples) group->first.push_back(warning.text);
  }
  return groups;
}

Result<PoseGraph> parse_g2o(const std::string& text, const std::string& source_name) {
  PoseGraph graph;
  bool seen_2d = false, seen_3d = false;
  std::istringstream lines(text);
  std::string line;
  int number = 0;
  std::set<Key> known;
  while (std::getline(lines, line)) {
    ++number;
    std::istringstream fields(line);
    std::string tag;
    if (!(fields >> tag) || tag[0] == '#') continue;
    const auto fail = [&](const std::string& what) { return Error(fmt::format("{}:{}: {}: {}", source_name, number, tag, what)); };
    std::vector<double> numbers;
    std::string token;
    while (fields >> token) {
      char* end = nullptr;
      const double value = std::strtod(token.c_str(), &end);
      if (end == token.c_str() || *end != '\0') return fail(fmt::format("'{}' is not a number", token));
      if (!std::isfinite(value)) return fail(fmt::format("non-finite value {}", token));
      numbers.push_back(value);
    }
    const auto id_at = [&](size_t i) -> Result<Key> {
      const double id = numbers[i];
      if (id < 0 || id != std::floor(id) || id > 1e15) return fail(fmt::format("vertex id {} is not a whole number >= 0", id));
      return X(static_cast<uint64_t>(id));
    };
    const auto expect = [&](size_t count) -> Status {
      if (numbers.size() != count) return fail(fmt::format("expected {} numbers, got {}", count, numbers.size()));
      return ok_status();
    };
    if (tag == "VERTEX_SE2" || tag == "VERTEX_SE3:QUAT") {
      const bool is_3d = tag == "VERTEX_SE3:QUAT";
      HANZO_RETURN_IF_ERROR(expect(is_3d ? 8 : 4));
      Key key = 0;
      HANZO_ASSIGN_OR_RETURN(key, id_at(0));
      if (known.count(key)) return fail(fmt::format("vertex {} appears twice", symbol_index(key)));
      if (is_3d) {
        SO3 rotation;
        HANZO_ASSIGN_OR_RETURN(rotation, with_context(unit_rotation(numbers[4], numbers[5], numbers[6], numbers[7]), fmt::format("{}:{}", source_name, number)));
        graph.initial.insert(key, SE3(rotation, Eigen::Vector3d(numbers[1], numbers[2], numbers[3])));
      } else {
        graph.initial.insert(key, SE2(numbers[3], Eigen::Vector2d(numbers[1], numbers[2])));
      }
      (is_3d ? seen_3d : seen_2d) = true;
      known.insert(key);
      graph.vertices.push_back(key);
    } else if (tag == "EDGE_SE2" || tag == "EDGE_SE3:QUAT") {
      const bool is_3d = tag == "EDGE_SE3:QUAT";
      HANZO_RETURN_IF_ERROR(expect(is_3d ? 30 : 11));
      PoseGraphEdge edge;
      HANZO_ASSIGN_OR_RETURN(edge.from, id_at(0));
      HANZO_ASSIGN_OR_RETURN(edge.to, id_at(1));
      if (edge.from == edge.to) return fail("an edge from a vertex to itself");
      if (is_3d) {
        SO3 rotation;
        HANZO_ASSIGN_OR_RETURN(rotation, with_context(unit_rotation(numbers[5], numbers[6], numbers[7], numbers[8]), fmt::format("{}:{}", source_name, number)));
        edge.measurement = SE3(rotation, Eigen::Vector3d(numbers[2], numbers[3], numbers[4]));
        edge.file_information = from_upper_triangle(std::vector<double>(numbers.begin() + 9, numbers.end()), 6);
      } else {
        edge.measurement = SE2(numbers[4], Eigen::Vector2d(numbers[2], numbers[3]));
        edge.file_information = from_upper_triangle(std::vector<double>(numbers.begin() + 5, numbers.end()), 3);
      }
      take_information(edge, graph, fmt::format("{}:{}: {}", source_name, number, tag));
      (is_3d ? seen_3d : seen_2d) = true;
      graph.edges.push_back(std::move(edge));
    } else if (tag == "VERTEX2" || tag == "VERTEX3") {  // TORO
      const bool is_3d = tag == "VERTEX3";
      HANZO_RETURN_IF_ERROR(expect(is_3d ? 7 : 4));
      Key key = 0;
      HANZO_ASSIGN_OR_RETURN(key, id_at(0));
      if (known.count(key)) return fail(fmt::format("vertex {} appears twice", symbol_index(key)));
      if (is_3d) {
        graph.initial.insert(key, SE3(from_roll_pitch_yaw(numbers[4], numbers[5], numbers[6]), Eigen::Vector3d(numbers[1], numbers[2], numbers[3])));
      } else {
        graph.initial.insert(key, SE2(numbers[3], Eigen::Vector2d(numbers[1], numbers[2])));
      }
      (is_3d ? seen_3d : seen_2d) = true;
      known.insert(key);
      graph.vertices.push_back(key);
    } else if (tag == "EDGE2" || tag == "EDGE3") {  // TORO
      const bool is_3d = tag == "EDGE3";
      HANZO_RETURN_IF_ERROR(expect(is_3d ? 29 : 11));
      PoseGraphEdge edge;
      HANZO_ASSIGN_OR_RETURN(edge.from, id_at(0));
      HANZO_ASSIGN_OR_RETURN(edge.to, id_at(1));
      if (edge.from == edge.to) return fail("an edge from a vertex to itself");
      if (is_3d) {
        edge.measurement = SE3(from_roll_pitch_yaw(numbers[5], numbers[6], numbers[7]), Eigen::Vector3d(numbers[2], numbers[3], numbers[4]));
        const Eigen::MatrixXd D = toro_to_g2o_scaling();
        edge.file_information = D * from_upper_triangle(std::vector<double>(numbers.begin() + 8, numbers.end()), 6) * D;
      } else {
        edge.measurement = SE2(numbers[4], Eigen::Vector2d(numbers[2], numbers[3]));
        edge.file_information = toro_2d_information(numbers.data() + 5);
      }
      take_information(edge, graph, fmt::format("{}:{}: {}", source_name, number, tag));
      (is_3d ? seen_3d : seen_2d) = true;
      graph.edges.push_back(std::move(edge));
    } else if (tag == "EQUIV") {  // TORO vertex equivalences: not supported, skipped
      HANZO_RETURN_IF_ERROR(expect(2));
      ++graph.skipped_equivalences;
    } else if (tag == "FIX") {
      for (size_t i = 0; i < numbers.size(); ++i) {
        Key key = 0;
        HANZO_ASSIGN_OR_RETURN(key, id_at(i));
        graph.fixed.push_back(key);
      }
    } else {
      return fail("unknown tag (expected VERTEX_SE2, EDGE_SE2, VERTEX_SE3:QUAT, EDGE_SE3:QUAT, FIX, or TORO's VERTEX2, EDGE2, VERTEX3, EDGE3, EQUIV)");
    }
    if (seen_2d && seen_3d) return fail("2D and 3D elements in one file");
  }
  if (graph.edges.empty()) return Error(fmt::format("{}: no edges", source_name));
  graph.dimension = seen_3d ? 3 : 2;
  for (const WarningGroup& group : group_warnings(graph.warnings)) {
    for (const std::string& example : group.first) logger()->warn("{}", example);
    if (group.count > group.first.size()) logger()->warn("{}: {} more edges with the same warning ({})", source_name, group.count - group.first.size(), group.kind);
  }

  // Vertices without a VERTEX line: chain edges from known vertices (the first edge's start
  // is the origin when nothing is known).
  if (known.empty()) {
    const Key start = graph.edges.front().from;
    graph.initial.insert(start, graph.dimension == 3 ? Value(SE3()) : Value(SE2()));
    known.insert(start);
    graph.vertices.push_back(start);
  }
  for (bool changed = true; changed;) {
    changed = false;
    for (const PoseGraphEdge& edge : graph.edges) {
      const bool has_from = known.count(edge.from) != 0, has_to = known.count(edge.to) != 0;
      if (has_from == has_to) continue;
      const Key target = has_from ? edge.to : edge.from;
      const Value value = has_from ? compose(graph.initial.all().at(edge.from), edge.measurement)
                                   : compose(graph.initial.all().at(edge.to), inverse(edge.measurement));
      graph.initial.insert(target, value);
      known.insert(target);
      graph.vertices.push_back(target);
      changed = true;
    }
  }
  for (const PoseGraphEdge& edge : graph.edges) {
    for (Key key : {edge.from, edge.to}) {
      if (!known.count(key)) return Error(fmt::format("{}: vertex {} is not connected to the rest of the graph", source_name, symbol_index(key)));
    }
  }
  if (graph.fixed.empty()) graph.fixed.push_back(graph.vertices.front());
  return graph;
}

Result<PoseGraph> read_g2o(const std::string& path) {
  std::ifstream file(path);
  if (!file) return Error(fmt::format("{}: cannot open file", path));
  std::stringstream buffer;
  buffer << file.rdbuf();
  return parse_g2o(buffer.str(), path);
}

SeSyncWeights se_sync_weights(const PoseGraphEdge& edge, int d) {
  const Eigen::MatrixXd& information =
      edge.file_information.size() > 0 && se_sync_blocks_usable(edge.file_information, d) ? edge.file_information : edge.information;
  const double tau = d / information.topLeftCorner(d, d).inverse().trace();
  const double kappa = d == 3 ? 3.0 / (2.0 * information.bottomRightCorner(3, 3).inverse().trace()) : information(2, 2);
  return {kappa, tau};
}

Result<FactorGraph> PoseGraph::factor_graph(Objective objective) const {
  FactorGraph graph;
  for (const PoseGraphEdge& edge : edges) {
    if (objective == Objective::kChordal) {
      const auto [kappa, tau] = se_sync_weights(edge, dimension);
      if (dimension == 3) {
        graph.emplace<ChordalBetweenFactor<SE3>>(edge.from, edge.to, std::get<SE3>(edge.measurement), kappa, tau);
      } else {
        graph.emplace<ChordalBetweenFactor<SE2>>(edge.from, edge.to, std::get<SE2>(edge.measurement), kappa, tau);
      }
      continue;
    }
    Eigen::MatrixXd information = edge.information;
    if (dimension == 3) {
      Eigen::MatrixXd J = Eigen::MatrixXd::Identity(6, 6);
      J.bottomRightCorner(3, 3) *= 0.5;  // quaternion vector part = rotation vector / 2
      information = J.transpose() * information * J;
    }
    GaussianNoise noise;
    HANZO_ASSIGN_OR_RETURN(noise, GaussianNoise::from_information(information));
    if (dimension == 3) {
      graph.emplace<BetweenFactorSE3>(edge.from, edge.to, std::get<SE3>(edge.measurement), noise);
    } else {
      graph.emplace<BetweenFactorSE2>(edge.from, edge.to, std::get<SE2>(edge.measurement), noise);
    }
  }
  return graph;
}

Result<std::vector<GraphUpdate>> PoseGraph::incremental_updates(Objective objective) const {
  FactorGraph all;
  HANZO_ASSIGN_OR_RETURN(all, factor_graph(objective));
  if (vertices.empty()) return std::vector<GraphUpdate>{};
  // Vertices in the order edges first reach them, each starting at odometry from its neighbour.
  const Key first = fixed.empty() ? vertices.front() : fixed.front();
  std::map<Key, size_t> update_of;
  std::vector<GraphUpdate> updates(1);
  updates[0].values.insert(first, initial.exists(first) ? initial.all().at(first) : (dimension == 3 ? Value(SE3()) : Value(SE2())));
  update_of[first] = 0;
  const auto value_of = [&](Key key) { return updates[update_of.at(key)].values.all().at(key); };
  for (size_t e = 0; e < edges.size(); ++e) {
    const PoseGraphEdge& edge = edges[e];
    const bool from_known = update_of.count(edge.from) != 0, to_known = update_of.count(edge.to) != 0;
    if (!from_known && !to_known) {
      return Error(fmt::format("incremental updates: edge {} - {} (number {}) joins two vertices no earlier edge reached",
                               key_to_string(edge.from), key_to_string(edge.to), e + 1));
    }
    if (from_known && to_known) continue;
    const Key new_key = from_known ? edge.to : edge.from;
    const Value value = from_known ? compose(value_of(edge.from), edge.measurement) : compose(value_of(edge.to), inverse(edge.measurement));
    update_of[new_key] = updates.size();
    updates.emplace_back().values.insert(new_key, value);
  }
  // Each edge joins the update of whichever of its vertices arrives later (file order within).
  for (size_t e = 0; e < edges.size(); ++e) {
    updates[std::max(update_of.at(edges[e].from), update_of.at(edges[e].to))].factors.add(all.factors()[e]);
  }
  return updates;
}

namespace {

enum class TextFormat { kG2o, kToro };

// The numbers of a pose: x y theta (2D); x y z and qx qy qz qw (g2o) or roll pitch yaw (TORO).
std::string pose_fields(const Value& pose, TextFormat format) {
  const auto number = [](double value) { return format_double(value); };
  if (const auto* se2 = std::get_if<SE2>(&pose)) {
    return fmt::format("{} {} {}", number(se2->translation().x()), number(se2->translation().y()), number(se2->angle()));
  }
  const SE3& se3 = std::get<SE3>(pose);
  const Eigen::Vector3d& t = se3.translation();
  if (format == TextFormat::kToro) {
    const Eigen::Vector3d rpy = roll_pitch_yaw(se3.rotation());
    return fmt::format("{} {} {} {} {} {}", number(t.x()), number(t.y()), number(t.z()), number(rpy.x()), number(rpy.y()), number(rpy.z()));
  }
  const Eigen::Quaterniond& q = se3.rotation().quaternion();
  return fmt::format("{} {} {} {} {} {} {}", number(t.x()), number(t.y()), number(t.z()), number(q.x()), number(q.y()), number(q.z()),
                     number(q.w()));
}

// An edge's information in the file's layout: g2o's upper triangle as stored; TORO's 2D order
// (xx xy yy tt xt yt) and 3D roll-pitch-yaw scaling.
std::string information_fields(const Eigen::MatrixXd& information, TextFormat format) {
  std::string out;
  const auto add = [&out](double value) { out += fmt::format(" {}", format_double(value)); };
  if (format == TextFormat::kToro && information.rows() == 3) {
    for (const auto& [i, j] : {std::pair{0, 0}, {0, 1}, {1, 1}, {2, 2}, {0, 2}, {1, 2}}) add(information(i, j));
    return out;
  }
  Eigen::MatrixXd matrix = information;
  if (format == TextFormat::kToro) {
    const Eigen::MatrixXd D_inverse = toro_to_g2o_scaling().inverse();
    matrix = D_inverse * information * D_inverse;
  }
  for (int i = 0; i < matrix.rows(); ++i) {
    for (int j = i; j < matrix.cols(); ++j) add(matrix(i, j));
  }
  return out;
}

Status write_pose_graph(const std::string& path, const PoseGraph& graph, const Values& values, TextFormat format) {
  const bool toro = format == TextFormat::kToro, spatial = graph.dimension == 3;
  const char* vertex_tag = toro ? (spatial ? "VERTEX3" : "VERTEX2") : (spatial ? "VERTEX_SE3:QUAT" : "VERTEX_SE2");
  const char* edge_tag = toro ? (spatial ? "EDGE3" : "EDGE2") : (spatial ? "EDGE_SE3:QUAT" : "EDGE_SE2");
  std::string out;
  for (Key key : graph.vertices) {
    Value pose;
    if (spatial) {
      HANZO_ASSIGN_OR_RETURN(pose, values.at<SE3>(key));
    } else {
      HANZO_ASSIGN_OR_RETURN(pose, values.at<SE2>(key));
    }
    out += fmt::format("{} {} {}\n", vertex_tag, symbol_index(key), pose_fields(pose, format));
  }
  for (const PoseGraphEdge& edge : graph.edges) {
    out += fmt::format("{} {} {} {}{}\n", edge_tag, symbol_index(edge.from), symbol_index(edge.to), pose_fields(edge.measurement, format),
                       information_fields(edge.file_information.size() > 0 ? edge.file_information : edge.information, format));
  }
  if (!toro) {
    for (Key key : graph.fixed) out += fmt::format("FIX {}\n", symbol_index(key));
  }
  return yaml::write_file_atomically(path, out);
}

}  // namespace

Status write_g2o(const std::string& path, const PoseGraph& graph, const Values& values) {
  return write_pose_graph(path, graph, values, TextFormat::kG2o);
}

Status write_toro(const std::string& path, const PoseGraph& graph, const Values& values) {
  return write_pose_graph(path, graph, values, TextFormat::kToro);
}

Result<double> g2o_chi2(const PoseGraph& graph, const Values& values) {
  double chi2 = 0.0;
  for (const PoseGraphEdge& edge : graph.edges) {
    Eigen::VectorXd error;
    if (graph.dimension == 3) {
      SE3 Ti, Tj;
      HANZO_ASSIGN_OR_RETURN(Ti, values.at<SE3>(edge.from));
      HANZO_ASSIGN_OR_RETURN(Tj, values.at<SE3>(edge.to));
      const SE3 delta = std::get<SE3>(edge.measurement).inverse() * (Ti.inverse() * Tj);
      Eigen::Quaterniond q = delta.rotation().quaternion();
      if (q.w() < 0.0) q.coeffs() = -q.coeffs();
      error.resize(6);
      error << delta.translation(), q.x(), q.y(), q.z();
    } else {
      SE2 Ti, Tj;
      HANZO_ASSIGN_OR_RETURN(Ti, values.at<SE2>(edge.from));
      HANZO_ASSIGN_OR_RETURN(Tj, values.at<SE2>(edge.to));
      const SE2 delta = std::get<SE2>(edge.measurement).inverse() * (Ti.inverse() * Tj);
      error = Eigen::Vector3d(delta.translation().x(), delta.translation().y(), SE2::wrap_angle(delta.angle()));
    }
    chi2 += error.dot(edge.information * error);
  }
  return chi2;
}

Eigen::MatrixXd pose_rotation(const Value& pose) {
  if (const auto* se2 = std::get_if<SE2>(&pose)) return se2->rotation_matrix();
  return std::get<SE3>(pose).rotation().matrix();
}

Eigen::VectorXd pose_translation(const Value& pose) {
  if (const auto* se2 = std::get_if<SE2>(&pose)) return se2->translation();
  return std::get<SE3>(pose).translation();
}

Result<double> se_sync_objective(const PoseGraph& graph, const Values& values) {
  double objective = 0.0;
  for (const PoseGraphEdge& edge : graph.edges) {
    const auto from = values.all().find(edge.from), to = values.all().find(edge.to);
    if (from == values.all().end() || to == values.all().end()) {
      return Error(fmt::format("SE-Sync objective: no pose for {}", key_to_string(from == values.all().end() ? edge.from : edge.to)));
    }
    if (from->second.index() != edge.measurement.index() || to->second.index() != edge.measurement.index()) {
      return Error(fmt::format("SE-Sync objective: edge {} - {} joins poses of another dimension", key_to_string(edge.from), key_to_string(edge.to)));
    }
    const Eigen::MatrixXd Ri = pose_rotation(from->second), Rj = pose_rotation(to->second), R_measured = pose_rotation(edge.measurement);
    const Eigen::VectorXd ti = pose_translation(from->second), tj = pose_translation(to->second), t_measured = pose_translation(edge.measurement);
    const auto [kappa, tau] = se_sync_weights(edge, graph.dimension);
    objective += kappa * (Rj - Ri * R_measured).squaredNorm() + tau * (tj - ti - Ri * t_measured).squaredNorm();
  }
  return objective;
}

}  // namespace hanzo::fusion::graph
