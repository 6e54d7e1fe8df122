#include "dicom_values.h"

#include <cmath>
#include <sstream>

namespace organfit::dicom::detail {

std::vector<double> numbers(const std::string& value) {
  std::vector<double> out;
  std::stringstream ss(value);
  std::string item;
  while (std::getline(ss, item, '\\')) {
    try {
      out.push_back(std::stod(item));
    } catch (const std::exception&) {
      out.push_back(std::nan(""));
    }
  }
  return out;
}

}  // namespace organfit::dicom::detail
