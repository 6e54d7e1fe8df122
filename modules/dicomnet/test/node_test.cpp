// The node's address, and the failures a node can cause that need no DICOM server: a
// port nobody listens on, and a listener that never answers (the timeout). A real node
// (Orthanc) is in tests/cli/run_dicom_node_tests.sh.
#include "organfit/dicomnet/node.h"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>

#include "organfit/dicomnet/echo.h"
#include "organfit/dicomnet/find_series.h"
#include "organfit/dicomnet/store_files.h"

namespace organfit::dicomnet {
namespace {

std::string message_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(Node, ParsesAetHostPort) {
  const Node n = parse_node("ORTHANC@127.0.0.1:4242", "ct.node");
  EXPECT_EQ(n.aet, "ORTHANC");
  EXPECT_EQ(n.host, "127.0.0.1");
  EXPECT_EQ(n.port, 4242);
  EXPECT_EQ(n.text(), "ORTHANC@127.0.0.1:4242");
  EXPECT_EQ(parse_node("TPS_1@pacs.example-clinic.org:104", "x").host, "pacs.example-clinic.org");
}

TEST(Node, RefusesMalformedAddressesNamingTheKey) {
  for (const char* bad :
       {"ORTHANC", "127.0.0.1:4242", "@host:104", "ORTHANC@:104", "ORTHANC@host:", "ORTHANC@host:0",
        "ORTHANC@host:65536", "ORTHANC@host:12a", "ORTHANC@ho/st:104", "A_TITLE_OF_17_CHAR@h:1",
        "BACK\\SLASH@h:1", "   @h:1"}) {
    const std::string m = message_of([&] { parse_node(bad, "export.send_to"); });
    EXPECT_EQ(m.rfind("export.send_to: ", 0), 0u) << bad << " -> " << m;
    EXPECT_THROW(parse_node(bad, "k"), InputError) << bad;
  }
}

TEST(Node, ChecksOurOwnAeTitle) {
  EXPECT_NO_THROW(check_ae_title("ORGANFIT", "network.aet"));
  EXPECT_THROW(check_ae_title("", "network.aet"), InputError);
  EXPECT_THROW(check_ae_title("SEVENTEEN_CHARS_X", "network.aet"), InputError);
  EXPECT_THROW(check_ae_title("TAB\tX", "network.aet"), InputError);
}

/// A TCP port on 127.0.0.1 that accepts connections and never answers; closed with it.
class SilentListener {
 public:
  SilentListener() {
    fd_ = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = 0;
    EXPECT_EQ(bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    EXPECT_EQ(listen(fd_, 4), 0);
    socklen_t len = sizeof a;
    getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len);
    port_ = ntohs(a.sin_port);
  }
  ~SilentListener() { close(fd_); }
  int port() const { return port_; }

 private:
  int fd_ = -1;
  int port_ = 0;
};

/// A port nobody listens on: bound for a moment, then closed.
int closed_port() {
  SilentListener l;
  return l.port();
}

TEST(Node, NodeDownIsOneLineNamingTheNode) {
  const Node n = parse_node("ORTHANC@127.0.0.1:" + std::to_string(closed_port()), "k");
  NetworkOptions o;
  o.timeout_s = 5;
  try {
    echo(n, o);
    FAIL() << "echo to a closed port succeeded";
  } catch (const NodeError& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.rfind(n.text() + ": cannot connect", 0), 0u) << m;
    EXPECT_NE(m.find("refused"), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    EXPECT_EQ(static_cast<int>(e.code()), 2);
  }
}

TEST(Node, ASilentNodeTimesOut) {
  SilentListener l;
  const Node n = parse_node("ORTHANC@127.0.0.1:" + std::to_string(l.port()), "k");
  NetworkOptions o;
  o.timeout_s = 1;
  const auto start = std::chrono::steady_clock::now();
  const std::string m = message_of([&] {
    SeriesQuery q;
    q.study_uid = "1.2.3";
    find_series(n, o, q);
  });
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_EQ(m.rfind(n.text() + ": ", 0), 0u) << m;
  EXPECT_NE(m.find("1 s (network.timeout_s)"), std::string::npos) << m;
  EXPECT_LT(s, 5.0);
}

TEST(Node, NotADicomFileIsRefusedBeforeConnecting) {
  const std::string file = ::testing::TempDir() + "/not_dicom.dcm";
  FILE* f = std::fopen(file.c_str(), "w");
  std::fputs("not DICOM\n", f);
  std::fclose(f);
  // The port is closed: the file is refused before any connection is tried.
  const Node n = parse_node("ORTHANC@127.0.0.1:" + std::to_string(closed_port()), "k");
  EXPECT_THROW(store_files(n, NetworkOptions{}, {file}), InputError);
}

}  // namespace
}  // namespace organfit::dicomnet
