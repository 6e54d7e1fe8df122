// report.html's pieces: PNG and base64 encodings, the CT views' orientation, the page.
#include "organfit/report/report.h"

#include <gtest/gtest.h>
#include <zlib.h>

namespace organfit::report {
namespace {

TEST(Base64, MatchesRfc4648Vectors) {
  EXPECT_EQ(base64(""), "");
  EXPECT_EQ(base64("f"), "Zg==");
  EXPECT_EQ(base64("fo"), "Zm8=");
  EXPECT_EQ(base64("foo"), "Zm9v");
  EXPECT_EQ(base64("foobar"), "Zm9vYmFy");
}

TEST(PngGray, DecodesBackToThePixels) {
  const int w = 5, h = 3;
  std::vector<std::uint8_t> pixels(w * h);
  for (int i = 0; i < w * h; ++i)
    pixels[i] = static_cast<std::uint8_t>(17 * i);
  const std::string png = png_gray(w, h, pixels.data());
  ASSERT_EQ(png.substr(0, 8), std::string("\x89PNG\r\n\x1a\n", 8));
  // IHDR: width, height, 8-bit grey.
  auto u32 = [&](size_t at) {
    return (std::uint32_t(std::uint8_t(png[at])) << 24) |
           (std::uint32_t(std::uint8_t(png[at + 1])) << 16) |
           (std::uint32_t(std::uint8_t(png[at + 2])) << 8) | std::uint8_t(png[at + 3]);
  };
  EXPECT_EQ(png.substr(12, 4), "IHDR");
  EXPECT_EQ(u32(16), 5u);
  EXPECT_EQ(u32(20), 3u);
  // IDAT inflates to rows of (filter 0, pixels).
  const size_t idat = png.find("IDAT");
  ASSERT_NE(idat, std::string::npos);
  const std::uint32_t length = u32(idat - 4);
  std::vector<std::uint8_t> raw(h * (w + 1));
  uLongf raw_size = raw.size();
  ASSERT_EQ(uncompress(raw.data(), &raw_size, reinterpret_cast<const Bytef*>(png.data() + idat + 4),
                       length),
            Z_OK);
  ASSERT_EQ(raw_size, raw.size());
  for (int r = 0; r < h; ++r) {
    EXPECT_EQ(raw[r * (w + 1)], 0);
    for (int c = 0; c < w; ++c)
      EXPECT_EQ(raw[r * (w + 1) + 1 + c], pixels[r * w + c]);
  }
}

class Views : public ::testing::Test {
 protected:
  void SetUp() override {
    g.size = {20, 16, 10};
    g.spacing_mm = Eigen::Vector3d(1.0, 1.0, 2.0);
    hu.assign(static_cast<size_t>(g.voxel_count()), -1000.f);
    mask = geometry::LabelVolume(g);
    // A bright block at i 4..9, j 5..8, k 2..6, also the mask.
    for (int k = 2; k <= 6; ++k)
      for (int j = 5; j <= 8; ++j)
        for (int i = 4; i <= 9; ++i) {
          hu[static_cast<size_t>(g.linear_index(i, j, k))] = 240.f;
          mask.at(i, j, k) = 1;
        }
  }
  geometry::ImageGeometry g;
  std::vector<float> hu;
  geometry::LabelVolume mask;
};

TEST_F(Views, AxialViewIsTheSliceWithAnteriorUpAndPatientRightOnTheLeft) {
  const SliceView v =
      slice_view(g, hu, Plane::kAxial, 4, {0, 0, 0}, {19, 15, 9}, &mask, nullptr,
                 {Eigen::Vector3d(6, 6, 8.4), Eigen::Vector3d(6, 6, 14)}, {0.5, 3.0}, 1.0);
  EXPECT_EQ(v.width, 20);
  EXPECT_EQ(v.height, 16);
  EXPECT_EQ(v.left + v.right + v.top + v.bottom, "RLAP");
  EXPECT_EQ(v.gray[0][5 * 20 + 4], 255);  // 240 HU is the soft-tissue window's top (40 + 200)
  EXPECT_EQ(v.gray[0][0], 0);
  ASSERT_EQ(v.planning.size(), 1u);  // one outline around the block
  ASSERT_EQ(v.points.size(), 1u);    // z = 8.4 is within 1 mm of the plane z = 8; z = 14 is not
  EXPECT_NEAR(v.points[0].x_mm, 6.5, 1e-9);
  EXPECT_NEAR(v.points[0].residual_mm, 0.5, 1e-12);
}

TEST_F(Views, CoronalViewPutsSuperiorAtTheTop) {
  const SliceView v =
      slice_view(g, hu, Plane::kCoronal, 6, {0, 0, 0}, {19, 15, 9}, &mask, nullptr, {}, {}, 1.0);
  EXPECT_EQ(v.height, 10);
  EXPECT_EQ(v.top + v.bottom, "SI");
  // Row 0 is k = 9 (dark), row 9 - 6 = 3 is k = 6 (bright).
  EXPECT_EQ(v.gray[0][0 * 20 + 5], 0);
  EXPECT_EQ(v.gray[0][3 * 20 + 5], 255);
  EXPECT_DOUBLE_EQ(v.pixel_h_mm, 2.0);
  EXPECT_EQ(
      slice_view(g, hu, Plane::kSagittal, 5, {0, 0, 0}, {19, 15, 9}, nullptr, nullptr, {}, {}, 1.0)
          .left,
      "A");
}

/// An organ (a 10 mm cube at 40 HU) in a 40 mm CT whose rest is `around` HU.
WindowChoice window_for(float around) {
  geometry::ImageGeometry g;
  g.size = {40, 40, 40};
  g.spacing_mm = Eigen::Vector3d(1, 1, 1);
  std::vector<float> hu(static_cast<size_t>(g.voxel_count()), around);
  geometry::LabelVolume organ(g);
  for (int k = 15; k < 25; ++k)
    for (int j = 15; j < 25; ++j)
      for (int i = 15; i < 25; ++i) {
        organ.at(i, j, k) = 1;
        hu[static_cast<size_t>(g.linear_index(i, j, k))] = 40.f;
      }
  return choose_window(g, hu, organ);
}

TEST(CtWindows, TheOneWhoseLevelIsNearestTheSurroundingsMedian) {
  ASSERT_EQ(ct_windows().size(), 3u);
  EXPECT_STREQ(ct_windows()[window_for(-800).window].id, "lung");  // a lung tumour
  EXPECT_STREQ(ct_windows()[window_for(20).window].id, "soft");    // a prostate
  EXPECT_STREQ(ct_windows()[window_for(900).window].id, "bone");   // inside a bone
  const WindowChoice c = window_for(-800);
  EXPECT_DOUBLE_EQ(c.surroundings_median_hu, -800);
  // The 10 mm shell around a 10 mm cube: 30^3 - 10^3 voxels less the box's rounded corners.
  EXPECT_GT(c.surroundings_voxels, 10000);
  EXPECT_LT(c.surroundings_voxels, 30 * 30 * 30 - 1000);
}

TEST_F(Views, EveryWindowIsRendered) {
  const SliceView v =
      slice_view(g, hu, Plane::kAxial, 4, {0, 0, 0}, {19, 15, 9}, &mask, nullptr, {}, {}, 1.0);
  ASSERT_EQ(v.gray.size(), 3u);
  // 240 HU: the top of soft tissue's window and above lung's (150 HU): white in both;
  // (240 + 500) / 1800 of bone's. The background, -1000 HU: (350 / 1500) of lung's.
  EXPECT_EQ(v.gray[0][5 * 20 + 4], 255);
  EXPECT_EQ(v.gray[1][5 * 20 + 4], 255);
  EXPECT_EQ(v.gray[2][5 * 20 + 4], static_cast<int>(740.0 / 1800 * 255));
  EXPECT_EQ(v.gray[0][0], 0);
  EXPECT_EQ(v.gray[1][0], static_cast<int>(350.0 / 1500 * 255));
}

TEST(ReportHtml, HasTheSectionsEscapesTextAndShowsNoPatientUnlessGiven) {
  ReportInput in;
  in.run = {{"scene", {{"name", "a<b"}}},
            {"status", "ok"},
            {"warnings", {"fit: 2 points rejected"}},
            {"fit", {{"volume_change_pct", 1.7}, {"method", "spread"}}},
            {"model", {{"radius_mm", 1.0}}},
            {"export",
             {{"roi", "Prostate_fit"},
              {"volume_on_ct_grid_cm3", 34.7},
              {"contours", 13},
              {"checks", {{"topology_kept", false}, {"volume_difference_cm3", -0.22}}}}},
            {"stages", {{{"name", "fit"}, {"wall_s", 0.1}, {"peak_memory_mib", 50.0}}}},
            {"outputs", {"run.json"}}};
  in.history_csv =
      "step,wall_s,residual_mean_mm,residual_max_mm,volume_change_pct,ke\n0,0,2,3,0,1\n20,0.1,1,1."
      "5,0.2,0.1\n";
  in.residuals_mm = {0.2, 1.5};
  const std::string html = report_html(in);
  EXPECT_NE(html.find("organfit report: a&lt;b"), std::string::npos);
  EXPECT_NE(html.find("fit: 2 points rejected"), std::string::npos);
  EXPECT_NE(html.find("<h3>Structure for the planning system</h3>"), std::string::npos);
  // Labelled in words, with units and rounding; the key and raw value kept for checking.
  EXPECT_NE(html.find("<th>Name</th><td data-key=\"export.roi\" data-value=\"Prostate_fit\">"
                      "Prostate_fit</td>"),
            std::string::npos);
  EXPECT_NE(html.find("<th>Volume on the CT grid</th><td data-key=\"export.volume_on_ct_grid_cm3\" "
                      "data-value=\"34.7\">34.70&nbsp;cm3</td>"),
            std::string::npos);
  EXPECT_NE(html.find("data-key=\"export.checks.topology_kept\" data-value=\"false\" "
                      "class=\"bad\">no</td>"),
            std::string::npos);
  EXPECT_NE(html.find("data-key=\"export.checks.volume_difference_cm3\" data-value=\"-0.22\">"
                      "-0.22&nbsp;cm3</td>"),
            std::string::npos);
  EXPECT_NE(html.find("data-key=\"stages.fit.wall_s\" data-value=\"0.1\">0.10&nbsp;s</td>"),
            std::string::npos);
  EXPECT_NE(html.find("@page{size:A4"), std::string::npos);
  EXPECT_EQ(html.find("volume_on_ct_grid_cm3</th>"), std::string::npos);  // no raw key shown
  EXPECT_NE(html.find("volume changed by +1.70%"), std::string::npos);
  EXPECT_NE(html.find("1 of 2 points were never reached"), std::string::npos);
  EXPECT_NE(html.find("aria-label=\"error against run time\""), std::string::npos);
  EXPECT_EQ(html.find("Patient:"), std::string::npos);
  // No network: every "http" is the SVG namespace (an identifier, never fetched).
  int links = 0;
  for (size_t at = html.find("http"); at != std::string::npos; at = html.find("http", at + 1))
    links += html.compare(at, 26, "http://www.w3.org/2000/svg") != 0;
  EXPECT_EQ(links, 0);
  in.patient = "Doe^J (ID 7)";
  EXPECT_NE(report_html(in).find("Patient: Doe^J (ID 7)"), std::string::npos);
  // The volume warning is the run's own tolerance's (fit.volume_tolerance_pct).
  in.run["fit"]["volume_tolerance_pct"] = 2.0;
  EXPECT_EQ(report_html(in).find("volume changed by"), std::string::npos);
}

}  // namespace
}  // namespace organfit::report
