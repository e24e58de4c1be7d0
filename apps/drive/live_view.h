// act_drive --http [ADDR:]PORT: the live view. One page (no external resources) showing the frame as
// the model sees it (MJPEG), steering and throttle gauges with the policy's chunk ahead, timings and
// the current fault, with an e-stop, a resume button, mode changes and driving by hand (on-screen
// stick, keyboard). Served by Debian's cpp-httplib on its own threads; it only talks to the control
// loop through the Cockpit, so no client can slow or block a tick.
//
//   GET  /            the page                  GET /stats   the status as JSON
//   GET  /stream.mjpg the preprocessed frames   GET /frame.jpg   one of them
//   POST /estop       neutral until resumed; needs no token
//   POST /resume, /mode?mode=ai|manual|ai-steer, /manual?steering=S&throttle=T (-1..1)
//                     anything that can move the car: need the token printed at start-up, as the
//                     X-Act-Token header or a token parameter; 403 without it
#pragma once

#include <memory>
#include <string>

#include "apps/drive/camera.h"
#include "apps/drive/cockpit.h"

namespace act::drive {

struct LiveViewOptions {
  std::string address = "127.0.0.1";  ///< only this machine unless an address is given
  int port = 8887;                     ///< 0 = any free port (the one chosen is in url())
  int image_height = 0, image_width = 0;  ///< the model's input: frames are shown as it sees them
};

/// "[ADDR:]PORT" into `options`; throws act::Error(kInvalidArgument) naming the problem.
void parse_http_address(const std::string& text, LiveViewOptions& options);

class LiveView {
 public:
  /// Binds and starts serving; throws act::Error when the address cannot be bound.
  LiveView(LiveViewOptions options, Cockpit& cockpit, const FrameSource& frames);
  ~LiveView();
  LiveView(const LiveView&) = delete;
  LiveView& operator=(const LiveView&) = delete;

  std::string url() const;
  /// Required by everything that can move the car (random, per run).
  const std::string& token() const { return token_; }

 private:
  struct Server;
  /// The page, the stats and the model's view (frame and MJPEG stream): anyone may read them.
  void add_view_routes(Cockpit& cockpit, const FrameSource& frames);
  /// E-stop (open to all), then resume, mode and manual driving (token only).
  void add_control_routes(Cockpit& cockpit);
  /// Binds options_'s address and serves on a thread of its own.
  void listen();
  LiveViewOptions options_;
  std::string token_;
  int port_ = 0;
  std::unique_ptr<Server> server_;
};

/// The page (live_view_page.cc).
extern const char* const kLiveViewPage;

}  // namespace act::drive
