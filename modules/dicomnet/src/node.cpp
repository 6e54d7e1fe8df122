#include "organfit/dicomnet/node.h"

#include <fmt/format.h>

#include <cctype>

namespace organfit::dicomnet {

std::string Node::text() const {
  return fmt::format("{}@{}:{}", aet, host, port);
}

void check_ae_title(const std::string& aet, const std::string& what) {
  if (aet.empty() || aet.size() > 16)
    throw InputError(
        fmt::format("{}: an AE title has 1 to 16 characters, not {}", what, aet.size()));
  bool blank = true;
  for (const char c : aet) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 || u > 0x7E || c == '\\')
      throw InputError(
          fmt::format("{}: the AE title '{}' has a character DICOM does not allow "
                      "(printable ASCII, no backslash)",
                      what, echo(aet)));
    if (c != ' ') blank = false;
  }
  if (blank) throw InputError(what + ": an AE title may not be all spaces");
}

Node parse_node(const std::string& text, const std::string& what) {
  const auto at = text.find('@');
  const auto colon = text.rfind(':');
  if (at == std::string::npos || colon == std::string::npos || colon < at)
    throw InputError(
        fmt::format("{}: '{}' is not a DICOM node: write AET@host:port (e.g. "
                    "ORTHANC@127.0.0.1:4242)",
                    what, echo(text)));
  Node node;
  node.aet = text.substr(0, at);
  node.host = text.substr(at + 1, colon - at - 1);
  const std::string port = text.substr(colon + 1);
  check_ae_title(node.aet, what);
  if (node.host.empty()) throw InputError(fmt::format("{}: '{}' names no host", what, echo(text)));
  for (const char c : node.host)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '-' || c == '_'))
      throw InputError(
          fmt::format("{}: '{}' is not a host name or IPv4 address", what, echo(node.host)));
  bool digits = !port.empty() && port.size() <= 5;
  for (const char c : port)
    digits = digits && std::isdigit(static_cast<unsigned char>(c));
  if (!digits || std::stoi(port) < 1 || std::stoi(port) > 65535)
    throw InputError(
        fmt::format("{}: the port '{}' is not a number from 1 to 65535", what, echo(port)));
  node.port = std::stoi(port);
  return node;
}

}  // namespace organfit::dicomnet
