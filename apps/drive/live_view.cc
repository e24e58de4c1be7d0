#include "apps/drive/live_view.h"

#include <httplib.h>

#include <atomic>
#include <cstdio>
#include <random>
#include <thread>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "actengine/vision.h"
#include "apps/media/media_io.h"
#include "weights/blob/error.h"

namespace act::drive {
namespace {

// The MJPEG stream's rate: enough to watch the road, a small share of a Pi's CPU.
constexpr std::chrono::milliseconds kStreamPeriod{66};
// Worker threads: each open MJPEG stream holds one; the rest serve /stats and the buttons.
constexpr size_t kServerThreads = 6;

std::string random_token() {
  std::random_device device;
  char text[17];
  std::snprintf(text, sizeof text, "%08x%08x", device(), device());
  return text;
}

nlohmann::ordered_json status_json(const LiveStatus& s) {
  return {{"tick", s.tick},
          {"time_s", s.time_s},
          {"mode", mode_name(s.pilot.mode)},
          {"estopped", s.pilot.estopped},
          {"overridden", s.pilot.overridden},
          {"driver", s.driver},
          {"source", s.source},
          {"fault", s.fault},
          {"steering_us", s.command.steering_us},
          {"throttle_us", s.command.throttle_us},
          {"steering", s.steering},
          {"throttle", s.throttle},
          {"steering_ahead", s.steering_ahead},
          {"throttle_ahead", s.throttle_ahead},
          {"capture_age_ms", s.capture_age_ms},
          {"preprocess_ms", s.preprocess_ms},
          {"infer_ms", s.infer_ms},
          {"jitter_ms", s.jitter_ms},
          {"ticks", s.ticks},
          {"inferences", s.inferences},
          {"overruns", s.overruns},
          {"frame_index", s.frame_index},
          {"control_hz", s.control_hz}};
}

void reply_json(httplib::Response& res, int status, const nlohmann::ordered_json& body) {
  res.status = status;
  res.set_content(body.dump(), "application/json");
}

}  // namespace

struct LiveView::Server {
  httplib::Server http;
  std::thread thread;
  std::atomic<bool> stopping{false};
};

void parse_http_address(const std::string& text, LiveViewOptions& options) {
  const size_t colon = text.rfind(':');
  const std::string port = colon == std::string::npos ? text : text.substr(colon + 1);
  if (colon != std::string::npos) options.address = text.substr(0, colon);
  size_t used = 0;
  int value = -1;
  try {
    value = std::stoi(port, &used);
  } catch (const std::exception&) {
  }
  if (used != port.size() || value < 0 || value > 65535 || options.address.empty()) {
    fail(ErrorCode::kInvalidArgument, "--http '" + text + "': expected [ADDR:]PORT, e.g. 8887 or 0.0.0.0:8887");
  }
  options.port = value;
}

LiveView::LiveView(LiveViewOptions options, Cockpit& cockpit, const FrameSource& frames)
    : options_(std::move(options)), token_(random_token()), server_(std::make_unique<Server>()) {
  server_->http.new_task_queue = [] { return new httplib::ThreadPool(kServerThreads); };
  add_view_routes(cockpit, frames);
  add_control_routes(cockpit);
  listen();
}

void LiveView::add_view_routes(Cockpit& cockpit, const FrameSource& frames) {
  httplib::Server& http = server_->http;
  // The newest frame as the model sees it (after preprocessing), JPEG-encoded; empty before the first.
  const auto model_view_jpeg = [this, &frames] {
    std::vector<uchar> jpeg;
    const auto frame = frames.latest();
    std::vector<uint8_t> rgb;
    if (!frame || !frame_to_model_rgb(frame->bgr, options_.image_height, options_.image_width, rgb).ok()) return jpeg;
    cv::Mat bgr;
    cv::cvtColor(cv::Mat(options_.image_height, options_.image_width, CV_8UC3, rgb.data()), bgr, cv::COLOR_RGB2BGR);
    media::encode_image(".jpg", bgr, jpeg);
    return jpeg;
  };
  http.Get("/", [](const httplib::Request&, httplib::Response& res) { res.set_content(kLiveViewPage, "text/html"); });
  http.Get("/stats", [&cockpit](const httplib::Request&, httplib::Response& res) {
    reply_json(res, 200, status_json(cockpit.status()));
  });
  http.Get("/frame.jpg", [model_view_jpeg](const httplib::Request&, httplib::Response& res) {
    const std::vector<uchar> jpeg = model_view_jpeg();
    if (jpeg.empty()) return reply_json(res, 503, {{"error", "no frame yet"}});
    res.set_content(reinterpret_cast<const char*>(jpeg.data()), jpeg.size(), "image/jpeg");
  });
  http.Get("/stream.mjpg", [this, model_view_jpeg](const httplib::Request&, httplib::Response& res) {
    res.set_header("Cache-Control", "no-store");
    res.set_chunked_content_provider("multipart/x-mixed-replace; boundary=frame",
                                     [this, model_view_jpeg](size_t, httplib::DataSink& sink) {
      if (server_->stopping.load()) return false;
      const std::vector<uchar> jpeg = model_view_jpeg();
      if (!jpeg.empty()) {
        const std::string head = "--frame\r\nContent-Type: image/jpeg\r\nContent-Length: " + std::to_string(jpeg.size()) + "\r\n\r\n";
        if (!sink.write(head.data(), head.size()) || !sink.write(reinterpret_cast<const char*>(jpeg.data()), jpeg.size()) ||
            !sink.write("\r\n", 2)) {
          return false;
        }
      }
      std::this_thread::sleep_for(kStreamPeriod);
      return true;
    });
  });
}

void LiveView::add_control_routes(Cockpit& cockpit) {
  httplib::Server& http = server_->http;
  const auto authorized = [this](const httplib::Request& req, httplib::Response& res) {
    const std::string given = req.has_header("X-Act-Token") ? req.get_header_value("X-Act-Token") : req.get_param_value("token");
    if (given == token_) return true;
    reply_json(res, 403, {{"error", "this moves the car: it needs the token act_drive printed at start-up"}});
    return false;
  };
  http.Post("/estop", [&cockpit](const httplib::Request&, httplib::Response& res) {
    cockpit.estop();
    reply_json(res, 200, {{"ok", "e-stop: neutral until resumed"}});
  });
  http.Post("/resume", [&cockpit, authorized](const httplib::Request& req, httplib::Response& res) {
    if (!authorized(req, res)) return;
    cockpit.resume();
    reply_json(res, 200, {{"ok", "resumed"}});
  });
  http.Post("/mode", [&cockpit, authorized](const httplib::Request& req, httplib::Response& res) {
    if (!authorized(req, res)) return;
    const std::optional<DriveMode> mode = parse_mode(req.get_param_value("mode"));
    if (!mode) return reply_json(res, 400, {{"error", "mode must be ai, manual or ai-steer"}});
    cockpit.set_mode(*mode);
    reply_json(res, 200, {{"ok", std::string("mode ") + mode_name(*mode)}});
  });
  http.Post("/manual", [&cockpit, authorized](const httplib::Request& req, httplib::Response& res) {
    if (!authorized(req, res)) return;
    double steering = 0, throttle = 0;
    try {
      steering = std::stod(req.get_param_value("steering"));
      throttle = std::stod(req.get_param_value("throttle"));
    } catch (const std::exception&) {
      return reply_json(res, 400, {{"error", "steering and throttle must be numbers in -1..1"}});
    }
    cockpit.manual(steering, throttle);
    reply_json(res, 200, {{"ok", "manual"}});
  });
}

void LiveView::listen() {
  httplib::Server& http = server_->http;
  if (options_.port == 0) {
    port_ = http.bind_to_any_port(options_.address);
  } else {
    port_ = http.bind_to_port(options_.address, options_.port) ? options_.port : -1;
  }
  if (port_ <= 0) {
    fail(ErrorCode::kIoError, "--http: cannot listen on " + options_.address + ":" + std::to_string(options_.port) +
                                  " (in use, or not an address of this machine)");
  }
  server_->thread = std::thread([this] { server_->http.listen_after_bind(); });
}

LiveView::~LiveView() {
  server_->stopping.store(true);
  server_->http.stop();
  if (server_->thread.joinable()) server_->thread.join();
}

std::string LiveView::url() const { return "http://" + options_.address + ":" + std::to_string(port_) + "/"; }

}  // namespace act::drive
