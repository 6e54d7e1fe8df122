#pragma once
// The biomechanical ground truth of `organfit bench fit --fem`: an organ deformed by a FEM
// engine (GetFEM, nearly incompressible neo-Hookean; testdata/fem/fem_cases.py states the
// model) under a transrectal probe from posterior or bladder filling from superior.
//
// The organ's surface (its inside test sampled on a grid of a sixth of its equivalent
// cube's side, meshed by meshing::write_surface) and the script are hashed together with
// the load and the magnitudes; the script runs only when that folder is not in the cache
// yet, and prints its progress. The fields are read back as evaluation::SampledDisplacement.
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "organfit/evaluation/synthetic.h"

namespace organfit::bench {

struct FemCase {
  double magnitude_mm = 0;       ///< requested largest displacement
  double largest_mm = 0;         ///< the solution's largest displacement (within 1%)
  double volume_change_pct = 0;  ///< the FEM's own: integral of det F over the mesh, -1
  double indentation_mm = 0;     ///< the plate's travel that gives it
  std::shared_ptr<const evaluation::SampledDisplacement> field;  ///< planning -> deformed
};

struct FemCases {
  std::string load;         ///< "probe" or "bladder"
  nlohmann::json mesh;      ///< tetrahedra, nodes, dofs, ... (cases.json's "mesh")
  double solve_wall_s = 0;  ///< the script's wall time when it ran (0: from the cache)
  std::filesystem::path folder;
  /// one per magnitude, in increasing order; fewer when the FEM found no solution beyond
  /// some magnitude (the larger ones are left out, with a warning)
  std::vector<FemCase> cases;
};

/// The folder the cases are kept in: $ORGANFIT_FEM_CACHE, else $XDG_CACHE_HOME/organfit/fem,
/// else ~/.cache/organfit/fem.
std::filesystem::path default_fem_cache();

/// The FEM cases of `organ` (named `name` in the cache) under `load` at `magnitudes_mm`,
/// from `cache` or made there. Throws InputError naming the step when the surface cannot be
/// made, the script fails (its own message is on stderr) or its output cannot be read.
FemCases fem_cases(const geometry::Shape& organ, const std::string& name, const std::string& load,
                   const std::vector<double>& magnitudes_mm, const std::filesystem::path& cache);

}  // namespace organfit::bench
