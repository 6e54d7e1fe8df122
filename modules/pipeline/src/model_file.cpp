#include "organfit/pipeline/model_file.h"

#include <fmt/format.h>

#include <Eigen/LU>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string_view>

#include "organfit/geometry/counter_random.h"
#include "organfit/geometry/signed_distance.h"
#include "organfit/support/atomic_file.h"
#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::pipeline {
namespace {

constexpr const char* kFormat = "organfit-model";
constexpr int kFormatVersion = 1;

// The file's checksum, its last key: 16 hexadecimal digits of geometry::hash_bytes over the
// file's text before this key. The text it covers is the file's own bytes, so that damage
// or an edit after organfit wrote the file (a moved mask origin, a changed position: either
// is valid JSON and a plausible model) is found when the file is read.
constexpr std::string_view kChecksumKey = ",\"checksum\":\"";
constexpr int kChecksumDigits = 16;

std::string checksum_of(std::string_view text) {
  return fmt::format("{:016x}", geometry::hash_bytes(0, text.data(), text.size()));
}

nlohmann::json vec(const Eigen::Vector3d& v) {
  return {v.x(), v.y(), v.z()};
}

/// A dense matrix or vector's numbers in its storage order (column-major).
template <class Derived>
nlohmann::json flat(const Eigen::PlainObjectBase<Derived>& m) {
  return std::vector<double>(m.data(), m.data() + m.size());
}

/// A cropped organ (geometry::cropped_organ) run-length encoded: alternating runs of 0 and 1,
/// starting with 0, i fastest.
nlohmann::json mask_to_json(const geometry::LabelVolume& crop_mask) {
  const geometry::ImageGeometry& crop = crop_mask.geometry;
  std::vector<long long> runs;
  std::uint8_t current = 0;
  long long length = 0;
  for (const std::uint8_t v : crop_mask.labels) {
    if (v != current) runs.push_back(length), length = 0, current = v;
    ++length;
  }
  runs.push_back(length);
  const Eigen::Matrix3d& r = crop.direction;
  return {{"size", {crop.size[0], crop.size[1], crop.size[2]}},
          {"spacing_mm", vec(crop.spacing_mm)},
          {"origin_mm", vec(crop.origin_mm)},
          {"direction", flat(r)},  // column-major
          {"runs", runs}};
}

/// The fit's uncertainty as what its posterior is given: rebuilt from these, it is the
/// same function (the numbers are written with full double precision).
nlohmann::json uncertainty_to_json(const fitting::SurfaceUncertainty& u) {
  const fitting::SurfaceUncertaintyOptions& o = u.options();
  const fitting::PriorVarianceField& extra = u.prior_variance_field();
  return {{"kind", "gaussian_process"},
          {"prior_sd_mm", o.prior_sd_mm},
          {"length_mm", o.length_mm},
          {"noise_sd_mm", o.noise_sd_mm},
          {"resolution_sd_mm", o.resolution_sd_mm},
          {"max_points", o.max_points},
          {"local_observations", o.local_observations},
          {"points_mm", flat(u.points_mm())},
          {"residuals_mm", u.residuals_mm()},
          {"prior_variance",
           {{"at_mm", flat(extra.at_mm)}, {"variance_mm2", flat(extra.variance_mm2)}}}};
}

/// Throws std::invalid_argument naming the key on counts that do not match (the
/// uncertainty's own constructor checks the values).
std::shared_ptr<const fitting::SurfaceUncertainty> uncertainty_from_json(const nlohmann::json& j) {
  if (j.at("kind").get<std::string>() != "gaussian_process")
    throw std::invalid_argument("uncertainty.kind: only gaussian_process is known");
  fitting::SurfaceUncertaintyOptions o;
  o.prior_sd_mm = j.at("prior_sd_mm").get<double>();
  o.length_mm = j.at("length_mm").get<double>();
  o.noise_sd_mm = j.at("noise_sd_mm").get<double>();
  o.resolution_sd_mm = j.at("resolution_sd_mm").get<double>();
  o.max_points = j.at("max_points").get<int>();
  o.local_observations = j.at("local_observations").get<int>();
  auto columns = [](const std::vector<double>& v, const char* key) {
    if (v.size() % 3) throw std::invalid_argument(std::string(key) + " needs x, y, z per point");
    return Eigen::Map<const Eigen::Matrix3Xd>(v.data(), 3, static_cast<Eigen::Index>(v.size() / 3));
  };
  const auto xyz = j.at("points_mm").get<std::vector<double>>();
  const Eigen::Matrix3Xd points = columns(xyz, "uncertainty.points_mm");
  std::vector<Eigen::Vector3d> points_mm(static_cast<size_t>(points.cols()));
  for (Eigen::Index k = 0; k < points.cols(); ++k)
    points_mm[static_cast<size_t>(k)] = points.col(k);
  if (!points.allFinite()) throw std::invalid_argument("uncertainty.points_mm: not finite");
  const auto residuals = j.at("residuals_mm").get<std::vector<double>>();
  const auto& prior = j.at("prior_variance");
  const auto at = prior.at("at_mm").get<std::vector<double>>();
  const auto variance = prior.at("variance_mm2").get<std::vector<double>>();
  fitting::PriorVarianceField extra;
  extra.at_mm = columns(at, "uncertainty.prior_variance.at_mm");
  extra.variance_mm2 = Eigen::Map<const Eigen::VectorXd>(
      variance.data(), static_cast<Eigen::Index>(variance.size()));
  try {
    return std::make_shared<const fitting::SurfaceUncertainty>(points_mm, o, residuals,
                                                               std::move(extra));
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("uncertainty: ") + e.what());
  }
}

}  // namespace

void save_model(const fs::path& file, const ModelStageResult& m, const std::string& organ_name,
                const OrganLook& look, const std::optional<CtReference>& ct,
                const nlohmann::json& provenance, const fitting::SurfaceUncertainty* uncertainty) {
  nlohmann::ordered_json j;
  j["format"] = kFormat;
  j["format_version"] = kFormatVersion;
  j["provenance"] = provenance;
  j["organ"] = {{"name", organ_name},
                {"colour", look.colour},
                {"interpreted_type", look.interpreted_type},
                {"reference_volume_mm3", m.reference.volume_mm3(1)}};
  j["settings"] = to_json(m.settings);
  nlohmann::json shape = {{"kind", m.shape.kind_name()},
                          {"size_mm", vec(m.shape.size_mm)},
                          {"centre_mm", vec(m.shape.centre_mm)}};
  // The planning organ's volume levels, found once at planning rather than at every session
  // (0.28 s on a 1.5 L liver): a mask shape's own (found when the shape was made), else the
  // reference body's (fitting::planning_volume_levels takes the one the organ is).
  if (m.shape.mask) shape["mask"] = mask_to_json(geometry::cropped_organ(*m.shape.mask));
  const geometry::SignedDistance::VolumeLevels levels = fitting::planning_volume_levels(m);
  j["organ"]["volume_level_mm"] = levels.level_mm;
  j["organ"]["volume_level_by_slice_phase_mm"] = levels.by_slice_phase_mm;
  // The organ's and its particles' volumes before a fit (fitting::PlanningVolumes), measured
  // once at planning rather than at every session; a fitted model's are measured by its fit.
  if (!fitting::carries_fit(m)) {
    const fitting::PlanningVolumes v = fitting::planning_volumes(m);
    j["organ"]["planning_volumes"] = {{"voxel_mm", v.voxel_mm},
                                      {"organ_mm3", v.organ_mm3},
                                      {"particle_body_mm3", v.particle_body_mm3},
                                      {"fingerprint", fmt::format("{:016x}", v.fingerprint)}};
  }
  j["shape"] = shape;
  j["ct"] = ct ? nlohmann::json{{"folder", ct->folder},
                                {"series_instance_uid", ct->series_instance_uid},
                                {"frame_of_reference_uid", ct->frame_of_reference_uid},
                                {"structure_set", ct->structure_set}}
               : nlohmann::json(nullptr);
  j["lattice_spacing_mm"] = m.lattice_spacing_mm;
  j["particles"] = m.state.size();
  j["positions_mm"] = flat(m.state.x);
  if (m.skeleton) {
    j["skeleton"] = {{"nodes_mm", flat(m.skeleton->skeleton().nodes_mm)}};
  } else {
    j["skeleton"] = nullptr;
  }
  // A fitted model: how its reference follows the particles (fitting/embedded_body.h).
  if (fitting::carries_fit(m)) {
    const auto& map = m.global_map;
    j["embedding"] = {
        {"placed_positions_mm", flat(m.placed)},
        {"global_affine", flat(map.affine.a)},
        {"global_translation_mm", vec(map.affine.t)},
        {"global_shear_centre_mm", vec(map.shears.centre)},
        {"global_shears", flat(map.shears.c)},
        {"global_shear_fields",
         map.fields.empty()
             ? nlohmann::json(nullptr)
             : nlohmann::json{{"sigma_mm", map.fields.sigma_mm},
                              {"origin_mm", vec(map.fields.origin_mm)},
                              {"count",
                               {map.fields.count.x(), map.fields.count.y(), map.fields.count.z()}},
                              {"weights_mm", flat(map.fields.weights)}}},
        {"global_flow",
         map.flow.empty()
             ? nlohmann::json(nullptr)
             : nlohmann::json{
                   {"sigma_mm", map.flow.sigma_mm},
                   {"origin_mm", vec(map.flow.origin_mm)},
                   {"count", {map.flow.count.x(), map.flow.count.y(), map.flow.count.z()}},
                   {"potentials_mm", flat(map.flow.potentials)}}}};
  } else {
    j["embedding"] = nullptr;
  }
  j["uncertainty"] = uncertainty ? uncertainty_to_json(*uncertainty) : nlohmann::json(nullptr);
  std::string text = j.dump();
  text.pop_back();  // the object's closing brace: the checksum is its last key
  const std::string checksum = checksum_of(text);
  write_file_atomically(file, text + std::string(kChecksumKey) + checksum + "\"}\n");
}

std::string unchecked_model_warning(const fs::path& file, const SavedModel& saved) {
  if (saved.checksum_verified) return "";
  return file.string() +
         ": the model file has no checksum (written by an organfit before model files kept "
         "one): read as it is, not checked for changes since it was written";
}

SavedModel load_model(const fs::path& file) {
  const std::string where = file.string();
  auto fail = [&](const std::string& why) -> void { throw InputError(where + ": " + why); };
  std::ifstream in(file, std::ios::binary);
  if (!in) fail("cannot read the model file");
  const std::string text{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  if (in.bad()) fail("cannot read the model file");
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception&) {
    fail("not an organfit model (not JSON)");
  }
  if (!j.is_object() || !j.contains("format") || j.at("format") != kFormat)
    fail("not an organfit model (no 'format: organfit-model')");
  const auto version = j.find("format_version");
  if (version == j.end() || !version->is_number_integer() ||
      version->get<long long>() != kFormatVersion)
    fail(fmt::format("model format version {} is not {} (made by another organfit version)",
                     version == j.end() ? "0" : version->dump(), kFormatVersion));
  SavedModel saved;
  // The checksum, where organfit writes it (the last key), against the text before it.
  if (const auto given = j.find("checksum"); given != j.end()) {
    const size_t at = text.rfind(kChecksumKey);
    const bool well_formed =
        given->is_string() && given->get_ref<const std::string&>().size() == kChecksumDigits &&
        at != std::string::npos &&
        text.compare(at + kChecksumKey.size(), kChecksumDigits, given->get<std::string>()) == 0;
    if (!well_formed)
      fail(
          "checksum: not 16 hexadecimal digits as organfit writes them, last (the file was "
          "rewritten after organfit wrote it): use the file as written, or plan again");
    if (checksum_of(std::string_view(text).substr(0, at)) != given->get<std::string>())
      fail(
          "the file was changed or damaged after organfit wrote it (its checksum does not "
          "match its content): use the file as written, or plan again");
    saved.checksum_verified = true;
  }
  try {
    ModelStageResult& m = saved.model;
    m.settings = model_settings_from_json(j.at("settings"), where);
    const auto& pos = j.at("positions_mm").get_ref<const nlohmann::json::array_t&>();
    const long long n = j.at("particles").get<long long>();
    if (n < 2 || static_cast<long long>(pos.size()) != 3 * n)
      fail(fmt::format("{} particles but {} coordinates", n, pos.size()));
    particles::Positions x(3, n);
    for (long long i = 0; i < 3 * n; ++i) {
      x.data()[i] = pos[static_cast<size_t>(i)].get<double>();
      if (!std::isfinite(x.data()[i])) fail("a particle position is not finite");
    }
    m.state = particles::State(std::move(x));
    m.lattice_spacing_mm = j.at("lattice_spacing_mm").get<double>();
    if (!(m.lattice_spacing_mm > 0)) fail("lattice_spacing_mm must be > 0");

    const auto& shape = j.at("shape");
    // Three finite numbers (mm) at `key` of `parent`, or the file is refused naming the key.
    auto three = [&](const nlohmann::json& parent, const char* key, const std::string& name) {
      const nlohmann::json& v = parent.at(key);
      if (!v.is_array() || v.size() != 3 ||
          !std::all_of(v.begin(), v.end(),
                       [](const nlohmann::json& number) { return number.is_number(); }))
        fail(name + " needs 3 numbers");
      const Eigen::Vector3d out(v[0].get<double>(), v[1].get<double>(), v[2].get<double>());
      if (!out.allFinite()) fail(name + " needs 3 finite numbers");
      return out;
    };
    // The organ's box as planned (a mask organ's is written for the reader, the mask itself
    // is what is read): sizes > 0 either way.
    const Eigen::Vector3d shape_size = three(shape, "size_mm", "shape.size_mm"),
                          shape_centre = three(shape, "centre_mm", "shape.centre_mm");
    if (!(shape_size.array() > 0).all()) fail("shape.size_mm must be > 0 along each axis");
    // The organ's levels as planned, checked on the grid they lie on: the mask's, else the
    // reference body's. Files written before the levels by slice phase were kept have the
    // single level alone (older ones none): their levels are found again, and their planning
    // volumes, measured on the organ at its single level, measured again.
    const nlohmann::json& organ = j.at("organ");
    const bool by_phase = organ.contains("volume_level_by_slice_phase_mm");
    if (by_phase && !organ.contains("volume_level_mm"))
      fail("organ.volume_level_by_slice_phase_mm is given without organ.volume_level_mm");
    std::optional<geometry::SignedDistance::VolumeLevels> levels;
    if (by_phase) {
      levels.emplace();
      levels->level_mm = organ.at("volume_level_mm").get<double>();
      const nlohmann::json& phases = organ.at("volume_level_by_slice_phase_mm");
      if (!phases.is_array() || phases.size() != levels->by_slice_phase_mm.size() ||
          !std::all_of(phases.begin(), phases.end(),
                       [](const auto& value) { return value.is_number(); }))
        fail("organ.volume_level_by_slice_phase_mm needs 4 numbers");
      for (size_t q = 0; q < phases.size(); ++q)
        levels->by_slice_phase_mm[q] = phases[q].get<double>();
    }
    auto check_level = [&](const geometry::ImageGeometry& grid) {
      if (!levels) return;
      if (!geometry::could_be_volume_level(levels->level_mm, grid))
        fail("organ.volume_level_mm: not finite, or farther from 0 than a voxel");
      for (double c : levels->by_slice_phase_mm)
        if (!geometry::could_be_volume_level(c, grid))
          fail("organ.volume_level_by_slice_phase_mm: not finite, or farther from 0 than a voxel");
    };
    if (!shape.at("kind").is_string()) fail("shape.kind: the organ's kind of shape, a text");
    if (shape.contains("mask") != (shape.at("kind") == "mask"))
      fail("shape: a mask is given exactly when shape.kind is 'mask'");
    if (shape.contains("mask")) {
      const auto& mj = shape.at("mask");
      geometry::ImageGeometry g;
      for (int d = 0; d < 3; ++d)
        g.size[d] = mj.at("size").at(d).get<int>();
      g.spacing_mm = three(mj, "spacing_mm", "shape.mask.spacing_mm");
      g.origin_mm = three(mj, "origin_mm", "shape.mask.origin_mm");
      const std::vector<double> r = mj.at("direction").get<std::vector<double>>();
      if (r.size() != 9) fail("shape.mask.direction needs 9 numbers");
      g.direction = Eigen::Map<const Eigen::Matrix3d>(r.data());
      if (g.voxel_count() <= 0 || !(g.spacing_mm.array() > 0).all())
        fail("shape.mask has no voxels");
      auto mask = std::make_shared<geometry::LabelVolume>(g);
      size_t v = 0;
      std::uint8_t value = 0;
      for (const auto& run : mj.at("runs")) {
        const long long length = run.get<long long>();
        if (length < 0 || v + static_cast<size_t>(length) > mask->labels.size())
          fail("shape.mask runs overflow the grid");
        std::fill_n(mask->labels.begin() + static_cast<long>(v), length, value);
        v += static_cast<size_t>(length);
        value ^= 1;
      }
      if (v != mask->labels.size()) fail("shape.mask runs do not cover the grid");
      check_level(mask->geometry);
      m.shape = geometry::make_mask_shape(std::move(mask), levels);
    } else {
      m.shape = geometry::make_shape(shape.at("kind").get<std::string>(), shape_size, shape_centre);
    }
    const particles::CohesionParams cp = cohesion_params_from(m.settings);
    m.reference = fitting::reference_body(m.shape, cp.r0_mm);
    // The reference body is made again from the shape as it was at planning: the same
    // voxels, so the volume the file states (absent in no file written) is its volume.
    const nlohmann::json& stated = j.at("organ").at("reference_volume_mm3");
    const double rebuilt = m.reference.volume_mm3(1);
    if (!stated.is_number() || std::abs(stated.get<double>() - rebuilt) > 1e-9 * rebuilt)
      fail(
          fmt::format("organ.reference_volume_mm3: {} in the file, but its shape gives {} mm3 "
                      "here (the file was changed, or made by an organfit that built the "
                      "reference otherwise: plan again)",
                      stated.dump(), rebuilt));
    if (!m.shape.mask) check_level(m.reference.geometry);
    m.saved_planning_levels = levels;
    // Absent in models written before they were kept: measured by the fit then.
    if (by_phase && organ.contains("planning_volumes")) {
      const auto& v = j.at("organ").at("planning_volumes");
      fitting::PlanningVolumes p;
      p.voxel_mm = v.at("voxel_mm").get<double>();
      p.organ_mm3 = v.at("organ_mm3").get<double>();
      p.particle_body_mm3 = v.at("particle_body_mm3").get<double>();
      const std::string print = v.at("fingerprint").get<std::string>();
      if (print.size() != 16 ||
          !std::all_of(print.begin(), print.end(), [](char c) { return std::isxdigit(c); }))
        fail("organ.planning_volumes.fingerprint needs 16 hexadecimal digits");
      p.fingerprint = std::stoull(print, nullptr, 16);
      for (const double value : {p.voxel_mm, p.organ_mm3, p.particle_body_mm3})
        if (!(std::isfinite(value) && value > 0))
          fail("organ.planning_volumes: voxel_mm, organ_mm3 and particle_body_mm3 must be > 0");
      m.saved_planning_volumes = p;
    }
    std::optional<particles::Skeleton> skeleton;
    if (!j.at("skeleton").is_null()) {
      const auto nodes = j.at("skeleton").at("nodes_mm").get<std::vector<double>>();
      if (nodes.empty() || nodes.size() % 3) fail("skeleton.nodes_mm needs x, y, z per node");
      skeleton.emplace();
      skeleton->nodes_mm = Eigen::Map<const Eigen::Matrix3Xd>(
          nodes.data(), 3, static_cast<Eigen::Index>(nodes.size() / 3));
    }
    build_model_terms(m, skeleton ? &*skeleton : nullptr);
    if (j.contains("embedding") && !j.at("embedding").is_null()) {
      const auto& e = j.at("embedding");
      const auto placed = e.at("placed_positions_mm").get<std::vector<double>>();
      const auto a = e.at("global_affine").get<std::vector<double>>();
      const auto c = e.at("global_shears").get<std::vector<double>>();
      if (placed.size() != static_cast<size_t>(3 * n))
        fail("embedding.placed_positions_mm needs x, y, z per particle");
      // global_shears: 15 coefficients (fitting::QuadraticShears); models written before
      // its last two shears have 9.
      if (a.size() != 9) fail("embedding.global_affine needs 9 numbers");
      if (c.size() != 9 && c.size() != static_cast<size_t>(fitting::QuadraticShears::kCount))
        fail("embedding.global_shears needs 15 numbers (9 in models written before 2026-11)");
      m.placed = Eigen::Map<const Eigen::Matrix3Xd>(placed.data(), 3, static_cast<Eigen::Index>(n));
      m.global_map.affine.a = Eigen::Map<const Eigen::Matrix3d>(a.data());
      m.global_map.affine.t = three(e, "global_translation_mm", "embedding.global_translation_mm");
      m.global_map.shears.centre =
          three(e, "global_shear_centre_mm", "embedding.global_shear_centre_mm");
      m.global_map.shears.c.setZero();
      m.global_map.shears.c.head(static_cast<Eigen::Index>(c.size())) =
          Eigen::Map<const Eigen::VectorXd>(c.data(), static_cast<Eigen::Index>(c.size()));
      // A part of the map on a grid (the shear fields, the flow; absent in models written
      // before it): its spacing, first node, counts and numbers (`values`, size_of(counts)
      // of them), checked, then fill(sigma, origin, counts, numbers).
      auto read_grid_part = [&](const char* key, const char* values, auto&& size_of, auto&& fill) {
        if (!e.contains(key) || e.at(key).is_null()) return;  // absent in older models
        const std::string name = std::string("embedding.") + key;
        const auto& f = e.at(key);
        const double sigma = f.at("sigma_mm").get<double>();
        const Eigen::Vector3d origin = three(f, "origin_mm", name + ".origin_mm");
        const auto given = f.at("count").get<std::vector<int>>();
        const auto numbers = f.at(values).get<std::vector<double>>();
        if (given.size() != 3 || !(sigma > 0))
          fail(name + " needs sigma_mm > 0, origin_mm and 3 counts");
        Eigen::Vector3i counts;
        for (int axis = 0; axis < 3; ++axis) {
          if (given[axis] < 1 || given[axis] > 1000)
            fail(name + ".count must be 1 to 1000 along each axis");
          counts(axis) = given[axis];
        }
        const long long expected = size_of(counts);
        if (static_cast<long long>(numbers.size()) != expected)
          fail(fmt::format("{}.{} needs {} numbers, has {}", name, values, expected,
                           numbers.size()));
        const Eigen::Map<const Eigen::VectorXd> v(numbers.data(),
                                                  static_cast<Eigen::Index>(numbers.size()));
        if (!v.allFinite()) fail(name + ": not finite");
        fill(sigma, origin, counts, v);
      };
      read_grid_part(
          "global_shear_fields", "weights_mm",
          [](const Eigen::Vector3i& counts) {
            fitting::ShearFields f;
            f.count = counts;
            return 3LL * f.block();
          },
          [&](double sigma, const Eigen::Vector3d& origin, const Eigen::Vector3i& counts,
              const Eigen::VectorXd& v) {
            fitting::ShearFields& f = m.global_map.fields;
            f.sigma_mm = sigma, f.origin_mm = origin, f.count = counts, f.weights = v;
          });
      read_grid_part(
          "global_flow", "potentials_mm",
          [](const Eigen::Vector3i& counts) { return 3LL * counts.prod(); },
          [&](double sigma, const Eigen::Vector3d& origin, const Eigen::Vector3i& counts,
              const Eigen::VectorXd& v) {
            fitting::IncompressibleFlow& f = m.global_map.flow;
            f.sigma_mm = sigma, f.origin_mm = origin, f.count = counts, f.potentials = v;
          });
      if (!m.placed.allFinite() || !m.global_map.affine.a.allFinite() ||
          !m.global_map.shears.c.allFinite() ||
          std::abs(m.global_map.affine.a.determinant() - 1) > 1e-6)
        fail("embedding: not finite, or the global map does not keep volume (det != 1)");
    }
    saved.organ_name = j.at("organ").at("name").get<std::string>();
    if (organ.contains("colour")) {  // files written before the look was kept have none
      const nlohmann::json& given = organ.at("colour");
      if (!given.is_array() || given.size() != 3 ||
          !std::all_of(given.begin(), given.end(), [](const nlohmann::json& v) {
            return v.is_number_integer() && v.get<long long>() >= 0 && v.get<long long>() <= 255;
          }))
        fail("organ.colour: three integers from 0 to 255");
      const auto c = given.get<std::vector<int>>();
      saved.organ_look.colour = {c[0], c[1], c[2]};
    }
    if (organ.contains("interpreted_type"))
      saved.organ_look.interpreted_type = organ.at("interpreted_type").get<std::string>();
    if (!j.at("ct").is_null()) {
      const auto& c = j.at("ct");
      saved.ct = CtReference{
          c.at("folder").get<std::string>(), c.at("series_instance_uid").get<std::string>(),
          c.at("frame_of_reference_uid").get<std::string>(),
          c.contains("structure_set") ? c.at("structure_set").get<std::string>() : std::string()};
    }
    // Where the model came from, for the session's log and run.json.
    saved.provenance = j.value("provenance", nlohmann::json::object());
    if (saved.provenance.is_null()) saved.provenance = nlohmann::json::object();
    const nlohmann::json& from = saved.provenance;
    if (!from.is_object() ||
        (from.contains("modelling_wall_s") && !from["modelling_wall_s"].is_number()) ||
        (from.contains("scene") && !from["scene"].is_string()))
      fail("provenance: an object whose modelling_wall_s is a number and scene a text");
    if (j.contains("uncertainty") && !j.at("uncertainty").is_null())  // absent in older models
      saved.uncertainty = uncertainty_from_json(j.at("uncertainty"));
  } catch (const nlohmann::json::exception& e) {
    fail(std::string("malformed model: ") + e.what());
  } catch (const std::invalid_argument& e) {
    fail(std::string("invalid model: ") + e.what());
  }
  return saved;
}

}  // namespace organfit::pipeline
