#include "organfit/bench/fem_cases.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "organfit/itkbridge/itk_images.h"
#include "organfit/meshing/surface.h"
#include "organfit/support/error.h"
#include "organfit/support/interrupt.h"
#include "organfit/support/resources.h"

namespace fs = std::filesystem;

namespace organfit::bench {
namespace {

std::string read_bytes(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw InputError(file.string() + ": cannot read");
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// FNV-1a, 64 bits: names a cache folder by what made it.
std::uint64_t fnv1a(const std::string& bytes, std::uint64_t h = 14695981039346656037ULL) {
  for (unsigned char c : bytes)
    h = (h ^ c) * 1099511628211ULL;
  return h;
}

std::string shell_quoted(const std::string& s) {
  std::string q = "'";
  for (char c : s)
    q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

/// The organ's inside test on a grid of a sixth of its equivalent cube's side (a mask
/// shape's own CT grid would give TetGen thousands of surface triangles to keep).
geometry::LabelVolume coarse_mask(const geometry::Shape& organ) {
  const geometry::Aabb b = organ.bounds();
  const Eigen::Vector3d extent = b.max_mm - b.min_mm;
  const double volume = geometry::shape_volume_mm3(organ, std::cbrt(extent.prod()) / 40);
  const double h = std::cbrt(volume) / 6;
  geometry::LabelVolume mask;
  for (int a = 0; a < 3; ++a)
    mask.geometry.size[a] = static_cast<int>(std::ceil(extent[a] / h)) + 3;
  mask.geometry.spacing_mm = Eigen::Vector3d::Constant(h);
  mask.geometry.origin_mm = b.min_mm - Eigen::Vector3d::Constant(h);
  mask.labels.assign(static_cast<size_t>(mask.geometry.voxel_count()), 0);
  for (int k = 0; k < mask.geometry.size[2]; ++k)
    for (int j = 0; j < mask.geometry.size[1]; ++j)
      for (int i = 0; i < mask.geometry.size[0]; ++i)
        mask.labels[static_cast<size_t>(mask.geometry.linear_index(i, j, k))] =
            organ.inside(mask.geometry.index_to_physical(Eigen::Vector3d(i, j, k)));
  return mask;
}

}  // namespace

fs::path default_fem_cache() {
  if (const char* c = std::getenv("ORGANFIT_FEM_CACHE"); c && *c) return c;
  if (const char* x = std::getenv("XDG_CACHE_HOME"); x && *x)
    return fs::path(x) / "organfit" / "fem";
  if (const char* home = std::getenv("HOME"); home && *home)
    return fs::path(home) / ".cache" / "organfit" / "fem";
  return fs::temp_directory_path() / "organfit-fem";
}

FemCases fem_cases(const geometry::Shape& organ, const std::string& name, const std::string& load,
                   const std::vector<double>& magnitudes_mm, const fs::path& cache) {
  const fs::path script = ORGANFIT_FEM_SCRIPT;
  std::error_code ec;
  fs::create_directories(cache, ec);
  if (ec) throw InputError(cache.string() + ": cannot make the FEM cache folder: " + ec.message());
  std::string magnitudes;
  for (double m : magnitudes_mm)
    magnitudes += (magnitudes.empty() ? "" : ",") + fmt::format("{:g}", m);
  // Everything a run writes before its cases are complete carries its process id, so
  // that two runs sharing a cache (two benches at once) never write into each other's
  // files; the finished folder is renamed into place, and the first to finish wins.
  const std::string mine = fmt::format(".{}", static_cast<long>(::getpid()));
  const fs::path surface = cache / ("." + name + mine + ".surface.stl");
  meshing::write_surface(coarse_mask(organ), surface);
  const std::uint64_t key =
      fnv1a(load + "|" + magnitudes, fnv1a(read_bytes(script), fnv1a(read_bytes(surface))));
  FemCases out;
  out.load = load;
  out.folder = cache / fmt::format("{}-{}-{:016x}", name, load, key);
  if (fs::exists(out.folder / "cases.json", ec)) {
    fs::remove(surface, ec);
  } else {
    spdlog::info(
        "bench fit: FEM ground truth for {} under the {} ({} mm): solving with GetFEM "
        "into {}",
        name, load, magnitudes, out.folder.string());
    const fs::path part = out.folder.string() + ".part" + mine;
    fs::remove_all(part, ec);
    fs::create_directories(part, ec);
    if (ec) throw InputError(part.string() + ": cannot make the FEM work folder: " + ec.message());
    const fs::path kept_surface = part / "surface.stl";  // kept with the cases it made
    fs::rename(surface, kept_surface, ec);
    if (ec) throw InputError(kept_surface.string() + ": cannot move the surface: " + ec.message());
    const std::string command = fmt::format(
        "{} {} --surface {} --load {} --magnitudes {} --out {}",
        shell_quoted(ORGANFIT_SYSTEM_PYTHON), shell_quoted(script.string()),
        shell_quoted(kept_surface.string()), load, magnitudes, shell_quoted(part.string()));
    Stopwatch clock;
    int status = 0;
    try {
      status = run_command(command);  // stopped with organfit on SIGINT or SIGTERM
    } catch (...) {
      fs::remove_all(part, ec);
      throw;
    }
    if (status != 0) {
      fs::remove_all(part, ec);
      throw InputError(fmt::format(
          "bench fit --fem: {} failed for {} under the {} (exit {}; its message is above)",
          script.filename().string(), name, load,
          WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status)));
    }
    fs::rename(part, out.folder, ec);
    if (ec) {  // another run finished the same cases first: theirs are kept
      fs::remove_all(part, ec);
      if (!fs::exists(out.folder / "cases.json", ec))
        throw InputError(out.folder.string() + ": cannot keep the FEM cases");
    }
    out.solve_wall_s = clock.elapsed_s();
  }
  nlohmann::json report;
  try {
    report = nlohmann::json::parse(read_bytes(out.folder / "cases.json"));
    out.mesh = report.at("mesh");
    for (const auto& c : report.at("cases")) {
      FemCase fc;
      fc.magnitude_mm = c.at("magnitude_mm").get<double>();
      fc.largest_mm = c.at("largest_displacement_mm").get<double>();
      fc.volume_change_pct = c.at("volume_change_pct").get<double>();
      fc.indentation_mm = c.at("indentation_mm").get<double>();
      itkbridge::VectorVolume v =
          itkbridge::read_vector_volume(out.folder / c.at("field").get<std::string>());
      fc.field = std::make_shared<const evaluation::SampledDisplacement>(
          evaluation::make_sampled_displacement(v.geometry, std::move(v.xyz)));
      out.cases.push_back(std::move(fc));
    }
  } catch (const std::exception& e) {
    throw InputError((out.folder / "cases.json").string() + ": " + e.what());
  }
  if (out.cases.size() < magnitudes_mm.size())
    spdlog::warn(
        "bench fit --fem: {} under the {}: the FEM found no solution beyond {:.1f} mm; "
        "the larger magnitudes are left out",
        name, load, out.cases.empty() ? 0.0 : out.cases.back().largest_mm);
  return out;
}

}  // namespace organfit::bench
