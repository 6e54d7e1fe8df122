// VTK translation unit: plain inputs only.
#include <vtkCellArray.h>
#include <vtkFeatureEdges.h>
#include <vtkFloatArray.h>
#include <vtkFlyingEdges3D.h>
#include <vtkImageData.h>
#include <vtkLookupTable.h>
#include <vtkMassProperties.h>
#include <vtkMatrix3x3.h>
#include <vtkNew.h>
#include <vtkOBJWriter.h>
#include <vtkObject.h>
#include <vtkPLYWriter.h>
#include <vtkPointData.h>
#include <vtkPolyData.h>
#include <vtkPolyDataNormals.h>
#include <vtkSTLWriter.h>
#include <vtkTriangleFilter.h>
#include <vtkUnsignedCharArray.h>
#include <vtkWindowedSincPolyDataFilter.h>
#include <vtkXMLPolyDataWriter.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>

#include "organfit/meshing/plain_mesh.h"
#include "organfit/support/atomic_file.h"
#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::meshing {
namespace {

bool ends_with(const std::string& s, const std::string& e) {
  return s.size() > e.size() && s.compare(s.size() - e.size(), e.size(), e) == 0;
}

/// Signed volume by the divergence theorem: positive when normals point outward.
double signed_volume(vtkPolyData* poly) {
  double v = 0;
  vtkCellArray* polys = poly->GetPolys();
  vtkIdType n = 0;
  const vtkIdType* ids = nullptr;
  polys->InitTraversal();
  while (polys->GetNextCell(n, ids)) {
    if (n != 3) continue;
    double a[3], b[3], c[3];
    poly->GetPoint(ids[0], a);
    poly->GetPoint(ids[1], b);
    poly->GetPoint(ids[2], c);
    v += (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
          a[2] * (b[0] * c[1] - b[1] * c[0])) /
         6.0;
  }
  return v;
}

}  // namespace

std::string mesh_file_name_problem(const std::string& file) {
  for (const char* e : {".stl", ".vtp", ".ply", ".obj"})
    if (ends_with(file, e)) return "";
  return "unknown mesh format (use .stl, .vtp, .ply or .obj)";
}

PlainSurfaceReport vtk_write_surface(const PlainMask& m, const std::string& file, bool keep_mesh,
                                     const PointScalar* scalar) {
  const bool stl = ends_with(file, ".stl"), vtp = ends_with(file, ".vtp"),
             ply = ends_with(file, ".ply");
  if (!file.empty())
    if (const std::string why = mesh_file_name_problem(file); !why.empty())
      throw InputError(file + ": " + why);
  // A failure is ours to report in one line (below, TempPath's on a full disk, or out of
  // memory): VTK's own messages of it, several lines on stderr, are not shown.
  const bool vtk_messages = vtkObject::GetGlobalWarningDisplay();
  vtkObject::GlobalWarningDisplayOff();
  struct Restore {
    bool on;
    ~Restore() { vtkObject::SetGlobalWarningDisplay(on); }
  } restore{vtk_messages};
  const geometry::PlainGeometry& g = m.geometry;
  // Pad by one empty voxel all round so the surface closes at the grid border.
  const int nx = g.size[0] + 2, ny = g.size[1] + 2, nz = g.size[2] + 2;
  vtkNew<vtkImageData> image;
  image->SetDimensions(nx, ny, nz);
  image->SetSpacing(g.spacing_mm.data());
  double origin[3];
  for (int d = 0; d < 3; ++d) {  // origin of the padded grid: one voxel back along each axis
    origin[d] = g.origin_mm[d];
    for (int e = 0; e < 3; ++e)
      origin[d] -= g.direction[3 * d + e] * g.spacing_mm[e];
  }
  image->SetOrigin(origin);
  vtkNew<vtkMatrix3x3> direction;
  for (int d = 0; d < 3; ++d)
    for (int e = 0; e < 3; ++e)
      direction->SetElement(d, e, g.direction[3 * d + e]);
  image->SetDirectionMatrix(direction);
  vtkNew<vtkUnsignedCharArray> scalars;
  scalars->SetNumberOfTuples(static_cast<vtkIdType>(nx) * ny * nz);
  scalars->FillValue(0);
  long long inside = 0;
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        const unsigned char v = m.labels[i + static_cast<size_t>(g.size[0]) *
                                                 (j + static_cast<size_t>(g.size[1]) * k)] == 1;
        inside += v;
        scalars->SetValue(
            (i + 1) + static_cast<vtkIdType>(nx) * ((j + 1) + static_cast<vtkIdType>(ny) * (k + 1)),
            v);
      }
  if (inside == 0) throw InputError(file + ": the organ mask is empty, no surface to write");
  image->GetPointData()->SetScalars(scalars);

  vtkNew<vtkFlyingEdges3D> contour;
  contour->SetInputData(image);
  contour->SetValue(0, 0.5);
  contour->ComputeNormalsOff();
  vtkNew<vtkWindowedSincPolyDataFilter> smooth;
  smooth->SetInputConnection(contour->GetOutputPort());
  smooth->SetNumberOfIterations(20);
  smooth->SetPassBand(0.1);
  smooth->NonManifoldSmoothingOn();
  smooth->NormalizeCoordinatesOn();
  smooth->BoundarySmoothingOff();
  smooth->FeatureEdgeSmoothingOff();
  vtkNew<vtkPolyDataNormals> normals;
  normals->SetInputConnection(smooth->GetOutputPort());
  normals->ConsistencyOn();
  normals->AutoOrientNormalsOn();
  normals->SplittingOff();
  vtkNew<vtkTriangleFilter> triangles;
  triangles->SetInputConnection(normals->GetOutputPort());
  triangles->Update();
  vtkPolyData* surface = triangles->GetOutput();

  PlainSurfaceReport report;
  report.points = surface->GetNumberOfPoints();
  report.triangles = surface->GetNumberOfPolys();
  vtkNew<vtkFeatureEdges> edges;
  edges->SetInputData(surface);
  edges->BoundaryEdgesOn();
  edges->NonManifoldEdgesOff();
  edges->FeatureEdgesOff();
  edges->ManifoldEdgesOff();
  edges->Update();
  report.boundary_edges = edges->GetOutput()->GetNumberOfLines();
  edges->BoundaryEdgesOff();
  edges->NonManifoldEdgesOn();
  edges->Update();
  report.non_manifold_edges = edges->GetOutput()->GetNumberOfLines();
  vtkNew<vtkMassProperties> mass;
  mass->SetInputData(surface);
  mass->Update();
  report.enclosed_volume_mm3 = mass->GetVolume();
  report.area_mm2 = mass->GetSurfaceArea();
  report.signed_volume_mm3 = signed_volume(surface);
  if (keep_mesh) {
    report.vertex_mm.reserve(static_cast<size_t>(3 * report.points));
    for (vtkIdType p = 0; p < surface->GetNumberOfPoints(); ++p) {
      double x[3];
      surface->GetPoint(p, x);
      for (double v : x)
        report.vertex_mm.push_back(static_cast<float>(v));
    }
    vtkCellArray* polys = surface->GetPolys();
    vtkIdType n = 0;
    const vtkIdType* ids = nullptr;
    polys->InitTraversal();
    while (polys->GetNextCell(n, ids))
      if (n == 3)
        for (int c = 0; c < 3; ++c)
          report.triangle_ids.push_back(static_cast<int>(ids[c]));
  }
  if (file.empty()) return report;
  double scalar_range[2] = {0, 0};
  if (scalar) {
    vtkNew<vtkFloatArray> values;
    values->SetName(scalar->name.c_str());
    values->SetNumberOfTuples(surface->GetNumberOfPoints());
    for (vtkIdType p = 0; p < surface->GetNumberOfPoints(); ++p) {
      double x[3];
      surface->GetPoint(p, x);
      values->SetValue(p, static_cast<float>(scalar->at_mm(x)));
    }
    values->GetRange(scalar_range);
    surface->GetPointData()->AddArray(values);
  }

  TempPath temp(file);
  const std::string name = temp.path().string();
  int ok = 0;
  if (stl) {
    vtkNew<vtkSTLWriter> w;
    w->SetInputData(surface);
    w->SetFileTypeToBinary();
    w->SetFileName(name.c_str());
    ok = w->Write();
  } else if (vtp) {
    vtkNew<vtkXMLPolyDataWriter> w;
    w->SetInputData(surface);
    w->SetFileName(name.c_str());
    ok = w->Write();
  } else if (ply) {
    vtkNew<vtkPLYWriter> w;
    w->SetInputData(surface);
    vtkNew<vtkLookupTable> colours;
    if (scalar) {
      colours->SetHueRange(0.667, 0.0);  // blue to red
      colours->SetTableRange(0, std::max(scalar_range[1], 1e-6));
      colours->Build();
      w->SetArrayName(scalar->name.c_str());
      w->SetLookupTable(colours);
      w->SetColorModeToDefault();
      w->AddComment(scalar->name + ": vertex colour from blue (0) to red (" +
                    std::to_string(scalar_range[1]) + ")");
    }
    w->SetFileName(name.c_str());
    ok = w->Write();
  } else {
    vtkNew<vtkOBJWriter> w;
    w->SetInputData(surface);
    w->SetFileName(name.c_str());
    ok = w->Write();
  }
  if (!ok || !fs::exists(temp.path())) {
    check_room_left(temp.path().parent_path(), file);
    throw InputError(file + ": cannot write the mesh");
  }
  temp.commit();
  return report;
}

}  // namespace organfit::meshing
