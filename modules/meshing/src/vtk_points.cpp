// VTK translation unit: plain arrays only (see plain_mesh.h).
#include <vtkDataArray.h>
#include <vtkNew.h>
#include <vtkPLYReader.h>
#include <vtkPointData.h>
#include <vtkPolyData.h>
#include <vtkPolyDataReader.h>
#include <vtkXMLPolyDataReader.h>

#include <filesystem>

#include "organfit/meshing/plain_mesh.h"
#include "organfit/support/error.h"
#include "organfit/support/interrupt.h"

namespace organfit::meshing {

PlainPointSet vtk_read_points(const std::string& file) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(file, ec)) throw InputError(file + ": no such file");
  auto ends = [&](const char* e) {
    const std::string s(e);
    return file.size() >= s.size() && file.compare(file.size() - s.size(), s.size(), s) == 0;
  };
  // VTK's readers print their complaints over several lines, and its PLY reader faults on
  // a header cut short: organfit says what was wrong, in one line (ReadingInput).
  const ReadingInput reading(file.c_str(), "VTK");
  vtkPolyData* poly = nullptr;
  vtkNew<vtkPLYReader> ply;
  vtkNew<vtkPolyDataReader> legacy;
  vtkNew<vtkXMLPolyDataReader> xml;
  if (ends(".ply")) {
    ply->SetFileName(file.c_str());
    ply->Update();
    poly = ply->GetOutput();
  } else if (ends(".vtk")) {
    legacy->SetFileName(file.c_str());
    legacy->Update();
    if (!legacy->IsFilePolyData()) throw InputError(file + ": not VTK polydata");
    poly = legacy->GetOutput();
  } else if (ends(".vtp")) {
    xml->SetFileName(file.c_str());
    xml->Update();
    poly = xml->GetOutput();
  } else {
    throw InputError(file + ": unknown point-set format (use .csv, .ply, .vtk or .vtp)");
  }
  PlainPointSet out;
  if (!poly || poly->GetNumberOfPoints() == 0)
    throw InputError(file + ": no points (or not readable)");
  vtkDataArray* confidence =
      poly->GetPointData() ? poly->GetPointData()->GetArray("confidence") : nullptr;
  for (vtkIdType i = 0; i < poly->GetNumberOfPoints(); ++i) {
    double p[3];
    poly->GetPoint(i, p);
    out.xyz_mm.insert(out.xyz_mm.end(), {p[0], p[1], p[2]});
    out.confidence.push_back(confidence ? confidence->GetTuple1(i) : 1.0);
  }
  return out;
}

}  // namespace organfit::meshing
