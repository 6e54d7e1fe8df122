#include "organfit/report/report.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include "organfit/support/parallel.h"

namespace organfit::report {
namespace {

std::string esc(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

const char* residual_colour(double r) {
  return r < 1.0 ? "#2ca02c" : r < 2.0 ? "#ff9f1c" : "#d62728";
}

/// One value of run.json as the page shows it: a label in words, the unit, the decimals.
struct Field {
  const char* label;
  const char* key;  ///< dotted path into run.json, e.g. "fit.residual_mean_mm"
  const char* unit = "";
  int decimals = 0;
};

const nlohmann::json* lookup(const nlohmann::json& run, const std::string& key) {
  const nlohmann::json* at = &run;
  size_t from = 0;
  while (true) {
    const size_t dot = key.find('.', from);
    const std::string part = key.substr(from, dot == std::string::npos ? dot : dot - from);
    if (!at->is_object() || !at->contains(part)) return nullptr;
    at = &(*at)[part];
    if (dot == std::string::npos) return at;
    from = dot + 1;
  }
}

/// "0.31 mm", "yes", "Prostate_fit": the value in words, rounded to the field's decimals.
std::string shown(const nlohmann::json& v, const Field& f) {
  std::string text;
  if (v.is_boolean())
    text = v.get<bool>() ? "yes" : "no";
  else if (v.is_number_float())
    text = fmt::format("{:.{}f}", v.get<double>(), f.decimals);
  else if (v.is_number())
    text = v.dump();
  else if (v.is_string())
    text = v.get<std::string>();
  else
    return esc(v.dump());
  return esc(text) + (f.unit[0] && v.is_number() ? std::string("&nbsp;") + f.unit : "");
}

/// A table of the fields run.json has (the others are left out), each cell carrying its
/// key and raw value.
std::string fields_table(const nlohmann::json& run, const std::vector<Field>& fields) {
  std::string rows;
  for (const Field& f : fields) {
    const nlohmann::json* v = lookup(run, f.key);
    if (!v || v->is_null() || v->is_object() || v->is_array()) continue;
    const char* cls = v->is_boolean() ? (v->get<bool>() ? " class=\"ok\"" : " class=\"bad\"") : "";
    rows += fmt::format(R"x(<tr><th>{}</th><td data-key="{}" data-value="{}"{}>{}</td></tr>)x",
                        esc(f.label), f.key,
                        esc(v->is_string() ? v->get<std::string>() : v->dump()), cls, shown(*v, f));
  }
  return rows.empty() ? "" : "<table>" + rows + "</table>";
}

/// "320 x 320 x 56" from [320, 320, 56] (decimals for sizes in mm).
std::string triple(const nlohmann::json& v, int decimals) {
  if (!v.is_array() || v.size() != 3) return "";
  std::string t;
  for (const auto& x : v)
    t += (t.empty() ? "" : " &times; ") + fmt::format("{:.{}f}", x.get<double>(), decimals);
  return t;
}

struct HistoryRow {
  double wall_s, mean, max, volume;
};

std::vector<HistoryRow> parse_history(const std::string& csv) {
  std::vector<HistoryRow> rows;
  std::istringstream in(csv);
  std::string line;
  std::getline(in,
               line);  // header: step,wall_s,residual_mean_mm,residual_max_mm,volume_change_pct,...
  while (std::getline(in, line)) {
    std::vector<double> v;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ','))
      v.push_back(std::atof(cell.c_str()));
    if (v.size() >= 5 && std::isfinite(v[1]) && std::isfinite(v[2]) && std::isfinite(v[3]) &&
        std::isfinite(v[4]))
      rows.push_back({v[1], v[2], v[3], v[4]});
  }
  return rows;
}

/// Data residual (mean, max; mm, left axis) and volume change (%, right axis) against
/// wall time (s).
std::string history_svg(const std::vector<HistoryRow>& rows) {
  if (rows.size() < 2) return "<p>No fit history.</p>";
  const double w = 640, h = 300, l = 60, r = 60, t = 20, b = 45;
  double t_max = 0, res_max = 0, vol_abs = 0.1;
  for (const auto& row : rows)
    t_max = std::max(t_max, row.wall_s), res_max = std::max(res_max, row.max),
    vol_abs = std::max(vol_abs, std::abs(row.volume));
  t_max = std::max(t_max, 1e-6), res_max = std::max(res_max * 1.1, 0.1), vol_abs *= 1.2;
  auto X = [&](double s) { return l + (w - l - r) * s / t_max; };
  auto Y = [&](double mm) { return t + (h - t - b) * (1 - mm / res_max); };
  auto YV = [&](double pct) { return t + (h - t - b) * (0.5 - 0.5 * pct / vol_abs); };
  auto line = [&](auto value, auto y, const char* colour, const char* dash) {
    std::string pts;
    for (const auto& row : rows)
      pts += fmt::format("{:.1f},{:.1f} ", X(row.wall_s), y(value(row)));
    return fmt::format(R"x(<polyline fill="none" stroke="{}" stroke-width="2" {} points="{}"/>)x",
                       colour, dash, pts);
  };
  std::string svg = fmt::format(
      R"x(<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {} {}" width="{}" height="{}" role="img" aria-label="error against run time">)x",
      w, h, w, h);
  svg +=
      fmt::format(R"x(<rect x="{}" y="{}" width="{}" height="{}" fill="#fafafa" stroke="#888"/>)x",
                  l, t, w - l - r, h - t - b);
  for (int i = 0; i <= 4; ++i) {
    const double mm = res_max * i / 4, s = t_max * i / 4, pct = vol_abs * (i - 2) / 2;
    svg += fmt::format(
        R"x(<text x="{:.1f}" y="{:.1f}" font-size="11" text-anchor="end">{:.2g}</text>)x", l - 4,
        Y(mm) + 4, mm);
    svg += fmt::format(
        R"x(<text x="{:.1f}" y="{:.1f}" font-size="11" text-anchor="middle">{:.3g}</text>)x", X(s),
        h - b + 15, s);
    svg +=
        fmt::format(R"x(<text x="{:.1f}" y="{:.1f}" font-size="11" fill="#1f77b4">{:+.2g}</text>)x",
                    w - r + 4, YV(pct) + 4, pct);
  }
  svg += line([](const HistoryRow& x) { return x.mean; }, Y, "#d62728", "");
  svg += line([](const HistoryRow& x) { return x.max; }, Y, "#d62728", "stroke-dasharray=\"5,4\"");
  svg += line([](const HistoryRow& x) { return x.volume; }, YV, "#1f77b4", "");
  svg += fmt::format(
      R"x(<text x="{}" y="{}" font-size="12" text-anchor="middle">wall time (s)</text>)x",
      l + (w - l - r) / 2, h - 8);
  svg += fmt::format(
      R"x(<text x="14" y="{}" font-size="12" transform="rotate(-90 14 {})" text-anchor="middle" fill="#d62728">data residual (mm): mean, max (dashed)</text>)x",
      t + (h - t - b) / 2, t + (h - t - b) / 2);
  svg += fmt::format(
      R"x(<text x="{}" y="{}" font-size="12" transform="rotate(90 {} {})" text-anchor="middle" fill="#1f77b4">volume change (%)</text>)x",
      w - 12, t + (h - t - b) / 2, w - 12, t + (h - t - b) / 2);
  return svg + "</svg>";
}

/// A plane as SVG: one image per window (the page's CSS shows the chosen one), the
/// contours and points on top, the patient's directions at the edges.
/// The uncertainty's colour: blue (0) to red (`scale_mm` and above).
std::string sigma_colour(double sigma_mm, double scale_mm) {
  const double f = std::clamp(sigma_mm / std::max(scale_mm, 1e-6), 0.0, 1.0);
  return fmt::format("hsl({:.0f},85%,50%)", 240 * (1 - f));
}

std::string view_svg(const SliceView& v, double sigma_scale_mm,
                     const std::string& attributes = "") {
  const double w = v.width * v.pixel_w_mm, h = v.height * v.pixel_h_mm;
  const double scale = 420.0 / std::max(w, h);  // screen pixels per mm
  std::string svg = fmt::format(
      R"x(<figure {}><svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {:.2f} {:.2f}" width="{:.0f}" height="{:.0f}" role="img" aria-label="{}">)x",
      attributes, w, h, w * scale, h * scale, esc(v.title));
  const auto& windows = ct_windows();
  for (size_t i = 0; i < v.gray.size() && i < windows.size(); ++i)
    svg += fmt::format(
        R"x(<image class="w-{}" x="0" y="0" width="{:.2f}" height="{:.2f}" preserveAspectRatio="none" href="data:image/png;base64,{}"/>)x",
        windows[i].id, w, h, base64(png_gray(v.width, v.height, v.gray[i].data())));
  auto outline = [&](const std::vector<Eigen::Vector2d>& line, const char* colour,
                     const char* dash) {
    std::string pts;
    for (const auto& p : line)
      pts += fmt::format("{:.2f},{:.2f} ", p.x(), p.y());
    return fmt::format(
        R"x(<polygon fill="none" stroke="{}" stroke-width="{:.2f}" {} points="{}"/>)x", colour,
        1.6 / scale, dash, pts);
  };
  for (const auto& line : v.planning)
    svg += outline(line, "#ffd400",
                   fmt::format("stroke-dasharray=\"{:.2f},{:.2f}\"", 4 / scale, 3 / scale).c_str());
  for (size_t l = 0; l < v.fitted.size(); ++l) {
    const auto& line = v.fitted[l];
    if (l < v.fitted_sigma_mm.size() && line.size() > 1) {
      // Coloured by sigma, segment by segment (each the mean of its two ends).
      const auto& s = v.fitted_sigma_mm[l];
      for (size_t i = 0; i < line.size(); ++i) {
        const size_t j = (i + 1) % line.size();
        svg += fmt::format(
            R"x(<line x1="{:.2f}" y1="{:.2f}" x2="{:.2f}" y2="{:.2f}" stroke="{}" stroke-width="{:.2f}"/>)x",
            line[i].x(), line[i].y(), line[j].x(), line[j].y(),
            sigma_colour(0.5 * (s[i] + s[j]), sigma_scale_mm), 2.2 / scale);
      }
    } else {
      svg += outline(line, "#00c8ff", "");
    }
  }
  for (const auto& p : v.points)
    svg += fmt::format(
        R"x(<circle cx="{:.2f}" cy="{:.2f}" r="{:.2f}" fill="{}" stroke="black" stroke-width="{:.2f}"><title>residual {:.2f} mm</title></circle>)x",
        p.x_mm, p.y_mm, 3.5 / scale, residual_colour(p.residual_mm), 0.6 / scale, p.residual_mm);
  const double fs = 13 / scale;
  svg += fmt::format(
      R"x(<g fill="white" font-size="{:.2f}" font-family="sans-serif"><text x="{:.2f}" y="{:.2f}">{}</text><text x="{:.2f}" y="{:.2f}" text-anchor="end">{}</text><text x="{:.2f}" y="{:.2f}" text-anchor="middle">{}</text><text x="{:.2f}" y="{:.2f}" text-anchor="middle">{}</text></g>)x",
      fs, 0.3 * fs, h / 2, v.left, w - 0.3 * fs, h / 2, v.right, w / 2, 1.1 * fs, v.top, w / 2,
      h - 0.4 * fs, v.bottom);
  return svg + "</svg><figcaption>" + esc(v.title) + "</figcaption></figure>";
}

/// The embedded 3D view: a painter's-algorithm renderer on a canvas (no WebGL needed).
constexpr const char* kViewerScript = R"JS(
(function () {
  const data = JSON.parse(document.getElementById('surface-data').textContent);
  const canvas = document.getElementById('surface');
  const ctx = canvas.getContext('2d');
  const v = data.v, t = data.t, pts = data.p, sig = data.s || null;
  const sigMax = Math.max(data.smax || 0, 1e-6);
  const n = v.length / 3;
  let c = [0, 0, 0];
  for (let i = 0; i < n; i++) for (let d = 0; d < 3; d++) c[d] += v[3 * i + d] / n;
  let radius = 1;
  for (let i = 0; i < n; i++) radius = Math.max(radius, Math.hypot(v[3 * i] - c[0], v[3 * i + 1] - c[1], v[3 * i + 2] - c[2]));
  let yaw = 0.6, pitch = -0.4;
  function project(x, y, z) {
    // Patient LPS to screen: x to the right, superior (+z) up, then turn.
    x -= c[0]; y -= c[1]; z -= c[2];
    const cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
    const x1 = cy * x + sy * y, y1 = -sy * x + cy * y;
    const up = cp * z - sp * y1, depth = sp * z + cp * y1;
    const s = 0.45 * Math.min(canvas.width, canvas.height) / radius;
    return [canvas.width / 2 + s * x1, canvas.height / 2 - s * up, depth];
  }
  function draw() {
    ctx.fillStyle = '#20242a';
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    const p = new Array(n);
    for (let i = 0; i < n; i++) p[i] = project(v[3 * i], v[3 * i + 1], v[3 * i + 2]);
    // Triangles and points in one back-to-front order, so the surface hides the points
    // behind it.
    const order = [];
    for (let k = 0; k < t.length; k += 3) order.push([(p[t[k]][2] + p[t[k + 1]][2] + p[t[k + 2]][2]) / 3, k]);
    for (let i = 0; i < pts.length; i++) order.push([project(pts[i][0], pts[i][1], pts[i][2])[2] - 0.5, -1 - i]);
    order.sort((x, y) => y[0] - x[0]);
    for (const [, k] of order) {
      if (k < 0) {
        const [x, y, z, r] = pts[-1 - k];
        const s = project(x, y, z);
        ctx.fillStyle = r < 1 ? '#2ca02c' : r < 2 ? '#ff9f1c' : '#d62728';
        ctx.beginPath(); ctx.arc(s[0], s[1], 3.5, 0, 2 * Math.PI); ctx.fill();
        continue;
      }
      const a = p[t[k]], b = p[t[k + 1]], q = p[t[k + 2]];
      // Lambert shading: how squarely the triangle faces the viewer.
      const ux = b[0] - a[0], uy = b[1] - a[1], uz = b[2] - a[2], wx = q[0] - a[0], wy = q[1] - a[1], wz = q[2] - a[2];
      const nx = uy * wz - uz * wy, ny = uz * wx - ux * wz, nz = ux * wy - uy * wx;
      const len = Math.hypot(nx, ny, nz) || 1;
      const shade = 0.25 + 0.75 * Math.abs(nz / len);
      if (sig) {
        // sigma: blue (0) to red (its largest), the hue of the triangle's mean.
        const f = Math.min(1, (sig[t[k]] + sig[t[k + 1]] + sig[t[k + 2]]) / (3 * sigMax));
        ctx.fillStyle = `hsl(${Math.round(240 * (1 - f))},80%,${Math.round(20 + 40 * shade)}%)`;
      } else {
        ctx.fillStyle = `rgb(${Math.round(60 * shade)},${Math.round(170 * shade)},${Math.round(230 * shade)})`;
      }
      ctx.beginPath(); ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]); ctx.lineTo(q[0], q[1]); ctx.closePath(); ctx.fill();
    }
  }
  let drag = null;
  canvas.addEventListener('pointerdown', e => { drag = [e.clientX, e.clientY]; });
  window.addEventListener('pointerup', () => { drag = null; });
  canvas.addEventListener('pointermove', e => {
    if (!drag) return;
    yaw += (e.clientX - drag[0]) * 0.01; pitch += (e.clientY - drag[1]) * 0.01; drag = [e.clientX, e.clientY]; draw();
  });
  draw();
  document.body.dataset.rendered = 'yes';
})();
)JS";

}  // namespace

/// The window buttons and the axial slice browser (#window=lung picks a window).
constexpr const char* kPageScript = R"JS(
(function () {
  const body = document.body;
  function pick(id) {
    if (!document.querySelector('button[data-window="' + id + '"]')) return;
    body.dataset.window = id;
    for (const b of document.querySelectorAll('button[data-window]')) b.classList.toggle('on', b.dataset.window === id);
  }
  for (const b of document.querySelectorAll('button[data-window]')) b.addEventListener('click', () => pick(b.dataset.window));
  const m = /window=(\w+)/.exec(location.hash);
  if (m) pick(m[1]);
  const slices = Array.from(document.querySelectorAll('figure.axial'));
  const range = document.getElementById('slice');
  const label = document.getElementById('slice-label');
  function show(i) {
    i = Math.max(0, Math.min(slices.length - 1, i));
    slices.forEach((f, k) => f.classList.toggle('current', k === i));
    if (range) range.value = i;
    if (label) label.textContent = (i + 1) + ' of ' + slices.length;
  }
  if (range) {
    range.addEventListener('input', () => show(Number(range.value)));
    document.getElementById('prev').addEventListener('click', () => show(Number(range.value) - 1));
    document.getElementById('next').addEventListener('click', () => show(Number(range.value) + 1));
    document.addEventListener('keydown', e => {
      if (e.key === 'ArrowUp' || e.key === 'PageUp') show(Number(range.value) + 1);
      if (e.key === 'ArrowDown' || e.key === 'PageDown') show(Number(range.value) - 1);
    });
    show(Number(range.value));
  }
})();
)JS";

std::string report_html(const ReportInput& in) {
  const nlohmann::json& run = in.run;
  const std::string name = run.contains("scene") ? run["scene"].value("name", "") : "";
  const std::string status = run.value("status", "");
  const auto& windows = ct_windows();
  const int chosen = std::clamp(in.window.window, 0, static_cast<int>(windows.size()) - 1);
  std::string window_css;
  for (const auto& w : windows)
    window_css += fmt::format("body[data-window={0}] image:not(.w-{0}){{display:none}}", w.id);
  std::string html;
  html += "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">";
  html +=
      "<title>organfit report: " + esc(name) +
      "</title><style>"
      "body{font-family:sans-serif;margin:24px;max-width:1400px;color:#222}"
      "table{border-collapse:collapse;margin:6px 0 14px}th,td{border:1px solid "
      "#ccc;padding:3px 8px;text-align:left}td[data-key]{text-align:right}"
      "th{background:#f2f2f2;font-weight:normal}.warn{background:#fff4e5;border-left:5px solid "
      "#ff9f1c;padding:8px 14px}.box{border:2px solid #0096c8;padding:0 12px}"
      ".ok{color:#2ca02c}.bad{color:#d62728}figure{display:inline-block;margin:6px}figcaption{"
      "text-align:center}"
      ".grid{display:flex;flex-wrap:wrap;gap:18px;align-items:flex-start}pre{background:#f7f7f7;"
      "padding:10px;overflow:auto}"
      "canvas{border:1px solid #888;touch-action:none}.legend span{margin-right:16px}"
      "button{margin-right:6px}button.on{font-weight:bold;background:#cde}"
      "figure.axial{display:none}figure.axial.current{display:inline-block}" +
      window_css +
      "@page{size:A4;margin:12mm}"
      "@media print{body{margin:0;max-width:none;font-size:9pt}.noprint{display:none}"
      "h2{break-after:avoid}table,figure,.box{break-inside:avoid}canvas{max-width:100%}"
      "svg{max-width:85mm;height:auto}}"
      "</style></head>";
  html += fmt::format("<body data-window=\"{}\">\n", windows[static_cast<size_t>(chosen)].id);
  html += fmt::format(
      "<h1>organfit report: {}</h1><p>organfit {} &middot; status <b class=\"{}\" "
      "data-key=\"status\" data-value=\"{}\">{}</b> &middot; wall time before this page "
      "{:.2f}&nbsp;s &middot; peak memory {:.0f} MiB</p>\n",
      esc(name), esc(run.value("organfit_version", "")), status == "ok" ? "ok" : "bad", esc(status),
      esc(status), run.value("wall_s", 0.0), run.value("peak_memory_mib", 0.0));
  if (!in.patient.empty()) html += "<p>Patient: " + esc(in.patient) + "</p>\n";

  // Warnings first: what a physicist must see before trusting the contour.
  std::vector<std::string> warnings;
  if (run.contains("warnings"))
    for (const auto& w : run["warnings"])
      warnings.push_back(w.get<std::string>());
  if (run.contains("fit")) {
    const auto& f = run["fit"];
    if (std::abs(f.value("volume_change_pct", 0.0)) > f.value("volume_tolerance_pct", 1.0))
      warnings.push_back(fmt::format("volume changed by {:+.2f}% during the fit",
                                     f.value("volume_change_pct", 0.0)));
    int far = 0;
    const double rho = run.contains("model") ? run["model"].value("radius_mm", 0.0) : 0.0;
    for (double r : in.residuals_mm)
      far += rho > 0 && r > rho;
    if (far > 0)
      warnings.push_back(fmt::format(
          "{} of {} points were never reached (residual above the particle radius {:.2f} mm)", far,
          in.residuals_mm.size(), rho));
  }
  if (!warnings.empty()) {
    html += "<div class=\"warn\"><b>Warnings</b><ul>";
    for (const auto& w : warnings)
      html += "<li>" + esc(w) + "</li>";
    html += "</ul></div>\n";
  }

  html += "<h2>Summary</h2><div class=\"grid\">";
  // The structure the planning system receives, and the export's checks of it against the
  // planning organ (pipeline/export_stage.h).
  if (run.contains("export") && run["export"].contains("roi"))
    html +=
        "<div class=\"box\"><h3>Structure for the planning system</h3>" +
        fields_table(run, {{"Name", "export.roi"},
                           {"Type", "export.roi_interpreted_type"},
                           {"Volume on the CT grid", "export.volume_on_ct_grid_cm3", "cm3", 2},
                           {"Contours (axial slices)", "export.contours"},
                           {"Topology kept (components, cavities)", "export.checks.topology_kept"},
                           {"Volume kept", "export.checks.volume_kept"},
                           {"Planning organ on the CT grid",
                            "export.checks.planning_volume_on_ct_grid_cm3", "cm3", 2},
                           {"Expected from the deformation",
                            "export.checks.expected_volume_on_ct_grid_cm3", "cm3", 2},
                           {"Difference", "export.checks.volume_difference_cm3", "cm3", 2},
                           {"Mean over the grid moved by parts of a voxel",
                            "export.checks.volume_on_shifted_grids.mean_cm3", "cm3", 2},
                           {"Tolerance", "export.checks.volume_tolerance_cm3", "cm3", 2},
                           {"Sent to", "export.sent.node"},
                           {"Send failed", "export.send_failed"}}) +
        "</div>";
  if (run.contains("fit"))
    html +=
        "<div><h3>Fit</h3>" +
        fields_table(
            run,
            {{"Method", "fit.method"},
             {"Converged", "fit.converged"},
             {"Stopped because", "fit.stop_reason"},
             {"Attractive points", "fit.attractive_points"},
             {"Rejected as outliers", "fit.rejected_points"},
             {"Mean distance to the points", "fit.residual_mean_mm", "mm", 2},
             {"95th percentile", "fit.residual_p95_mm", "mm", 2},
             {"Largest", "fit.residual_max_mm", "mm", 2},
             {"Volume change (deformation)", "fit.volume_change_pct", "%", 2},
             {"Volume change (voxels counted)", "fit.volume_change_counted_pct", "%", 2},
             {"Fit time", "fit.wall_s", "s", 2},
             {"Uncertainty sigma, median where seen", "fit.uncertainty.seen.median_mm", "mm", 2},
             {"Uncertainty sigma, median where unseen", "fit.uncertainty.unseen.median_mm", "mm",
              2},
             {"Uncertainty sigma, 95th percentile", "fit.uncertainty.all.p95_mm", "mm", 2}}) +
        "</div>";
  if (run.contains("truth"))
    html +=
        "<div><h3>Against the known truth</h3>" +
        fields_table(
            run,
            {{"Mean surface distance", "truth.msd_mm", "mm", 2},
             {"95% Hausdorff distance", "truth.hd95_mm", "mm", 2},
             {"Dice", "truth.dice", "", 3},
             {"Left as it was: mean surface distance", "truth.msd_undeformed_mm", "mm", 2},
             {"Left as it was: 95% Hausdorff", "truth.hd95_undeformed_mm", "mm", 2},
             {"The grid's own floor", "truth.msd_floor_mm", "mm", 2},
             {"Share of the change recovered", "truth.recovery", "", 2},
             {"True surface within 2 sigma (share)", "truth.uncertainty.within_2sd_share", "", 3},
             {"... where unseen", "truth.uncertainty.unseen_within_2sd_share", "", 3}}) +
        "</div>";
  if (run.contains("organ"))
    html += "<div><h3>Planning organ</h3>" +
            fields_table(run, {{"ROI", "organ.roi"},
                               {"From", "organ.source"},
                               {"Volume", "organ.volume_cm3", "cm3", 2},
                               {"Contours", "organ.contours"},
                               {"Contours matched by position", "organ.matched_by_position"}}) +
            "</div>";
  if (run.contains("model"))
    html += "<div><h3>Model</h3>" +
            fields_table(run, {{"Particles", "model.particles"},
                               {"Particle radius", "model.radius_mm", "mm", 2},
                               {"Skeleton nodes", "model.skeleton_nodes"},
                               {"Skeleton from", "model.skeleton_from"},
                               {"Particles' volume against the organ's",
                                "model.volume_vs_reference_pct", "%", 2},
                               {"Planning model", "model.from_planning_model"},
                               {"Planning scene", "model.planning_scene"}}) +
            "</div>";
  if (run.contains("ct")) {
    html += "<div><h3>CT</h3>" + fields_table(run, {{"Slices", "ct.slices"}});
    html += fmt::format(
        "<table><tr><th>Voxels</th><td>{}</td></tr><tr><th>Voxel size</th><td>{}&nbsp;mm</td>"
        "</tr>",
        triple(run["ct"].value("size", nlohmann::json()), 0),
        triple(run["ct"].value("spacing_mm", nlohmann::json()), 2));
    if (in.window.surroundings_voxels > 0)
      html += fmt::format(
          "<tr><th>Window</th><td>{} (median {:.0f} HU within 10 mm of the organ)</td></tr>",
          windows[static_cast<size_t>(chosen)].name, in.window.surroundings_median_hu);
    html += "</table></div>";
  }
  if (run.contains("timing"))
    html += "<div><h3>Modelling and update</h3>" +
            fields_table(
                run, {{"Initial modelling (this run)", "timing.modelling_s", "s", 2},
                      {"Initial modelling (planning run)", "timing.planning_modelling_s", "s", 2},
                      {"Session update", "timing.update_s", "s", 2}}) +
            "</div>";
  html +=
      "</div>\n<h2>Stages</h2><table><tr><th>stage</th><th>wall time</th><th>peak memory</th>"
      "</tr>";
  // The page cannot hold its own time: run.json has it once the page is written.
  if (run.contains("stages"))
    for (const auto& st : run["stages"])
      html +=
          st.value("name", "") == "report"
              ? "<tr><td>report</td><td>this page (in run.json)</td><td></td></tr>"
              : fmt::format(
                    "<tr><td>{}</td><td data-key=\"stages.{}.wall_s\" data-value=\"{}\">"
                    "{:.2f}&nbsp;s</td><td>{:.0f}&nbsp;MiB</td></tr>",
                    esc(st.value("name", "")), esc(st.value("name", "")), st.value("wall_s", 0.0),
                    st.value("wall_s", 0.0), st.value("peak_memory_mib", 0.0));
  html += "</table>\n";

  html += "<h2>Error against run time</h2>" + history_svg(parse_history(in.history_csv)) + "\n";
  if (!in.axial.empty() || !in.views.empty()) {
    html += "<h2>CT through the organ</h2><p class=\"noprint\">Window: ";
    for (const auto& w : windows)
      html += fmt::format("<button data-window=\"{}\" class=\"{}\">{}</button>", w.id,
                          &w == &windows[static_cast<size_t>(chosen)] ? "on" : "", w.name);
    html +=
        "</p><p class=\"legend\"><span style=\"color:#b59600\">- - "
        "planning contour</span><span style=\"color:#0096c8\">&mdash; fitted contour" +
        (in.sigma_scale_mm > 0
             ? fmt::format(" (coloured by sigma: <b style=\"color:hsl(240,85%,50%)\">0</b> to "
                           "<b style=\"color:hsl(0,85%,50%)\">{:.2f} mm</b>)",
                           in.sigma_scale_mm)
             : std::string()) +
        "</span>"
        "<span>points by residual: <b style=\"color:#2ca02c\">&lt; 1 mm</b>, <b "
        "style=\"color:#ff9f1c\">&lt; 2 mm</b>, <b style=\"color:#d62728\">&ge; 2 "
        "mm</b></span></p><div class=\"grid\">";
    if (!in.axial.empty()) {
      const int shown_first = std::clamp(in.axial_shown, 0, static_cast<int>(in.axial.size()) - 1);
      html += fmt::format(
          "<div><p class=\"noprint\"><button id=\"prev\">&darr; inferior</button><input "
          "id=\"slice\" type=\"range\" min=\"0\" max=\"{}\" value=\"{}\"><button "
          "id=\"next\">superior &uarr;</button> axial slice <span id=\"slice-label\"></span></p>",
          in.axial.size() - 1, shown_first);
      // Each slice's images encoded on its own, on threads (129 PNGs of a 1.5 L liver's
      // slices: 0.4 s on one), then set in order.
      std::vector<std::string> slices(in.axial.size());
      parallel_for_each(static_cast<int>(slices.size()), [&](int i) {
        slices[static_cast<size_t>(i)] =
            view_svg(in.axial[static_cast<size_t>(i)], in.sigma_scale_mm,
                     fmt::format("class=\"axial{}\"", i == shown_first ? " current" : ""));
      });
      for (const auto& slice : slices)
        html += slice;
      html += "</div>";
    }
    for (const auto& v : in.views)
      html += view_svg(v, in.sigma_scale_mm);
    html += "</div>\n";
  }
  if (!in.surface_triangles.empty()) {
    nlohmann::json data;
    std::vector<double> v;
    v.reserve(in.surface_vertex_mm.size());
    for (float x : in.surface_vertex_mm)
      v.push_back(std::round(x * 100.0) / 100.0);
    data["v"] = v;
    data["t"] = in.surface_triangles;
    if (!in.surface_sigma_mm.empty()) {
      std::vector<double> s;
      for (float x : in.surface_sigma_mm)
        s.push_back(std::round(x * 100.0) / 100.0);
      data["s"] = s;
      data["smax"] = in.sigma_scale_mm;
    }
    nlohmann::json pts = nlohmann::json::array();
    for (size_t p = 0; p < in.points_mm.size(); ++p)
      pts.push_back({in.points_mm[p].x(), in.points_mm[p].y(), in.points_mm[p].z(),
                     p < in.residuals_mm.size() ? in.residuals_mm[p] : 0.0});
    data["p"] = pts;
    std::string json = data.dump();
    // Inside <script>, "</" must not appear: JSON numbers and arrays never produce it.
    html += "<h2>Fitted surface</h2><p>Drag to turn. Points coloured by residual." +
            (in.surface_sigma_mm.empty()
                 ? std::string()
                 : fmt::format(" The surface coloured by its uncertainty sigma, the standard "
                               "deviation of where the true surface may lie: blue 0 mm to red "
                               "{:.2f}&nbsp;mm (the prior: no point near).",
                               in.sigma_scale_mm)) +
            "</p><canvas "
            "id=\"surface\" width=\"640\" height=\"480\"></canvas>\n";
    html += "<script type=\"application/json\" id=\"surface-data\">" + json +
            "</script>\n<script>" + kViewerScript + "</script>\n";
  } else {
    html += "<script>document.body.dataset.rendered = 'yes';</script>\n";
  }
  html += std::string("<script>") + kPageScript + "</script>\n";
  html += "<h2>Outputs</h2><ul>";
  if (run.contains("outputs"))
    for (const auto& o : run["outputs"])
      html += "<li>" + esc(o.get<std::string>()) + "</li>";
  html += "</ul><details class=\"noprint\"><summary>Scene (resolved)</summary><pre>" +
          esc(in.scene_yaml) + "</pre></details>\n";
  html += "</body></html>\n";
  return html;
}

}  // namespace organfit::report
