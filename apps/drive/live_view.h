// act_drive --http [ADDR:]PORT: the live view. One page (no external resources) showing the frame as
// the model sees it (MJPEG), steering and throttle gauges with the policy's chunk ahead, timings and
// the current fault, with an e-stop, a resume button, mode changes and driving by hand (on-screen
// stick, keyboard). Served by Debian's cpp-httplib, a thread per connection; it only talks to the
// control loop through the Cockpit, so no client can slow or block a tick.
//
//   GET  /            the page                  GET /stats   the status as JSON
//   GET  /stream.mjpg the preprocessed frames   GET /frame.jpg   one of them
//   POST /estop       neutral until resumed; needs no token, no body, no Content-Length
//   POST /resume, /mode?mode=ai|manual|ai-steer, /manual?steering=S&throttle=T (-1..1)
//                     anything that can move the car: need the token printed at start-up, as the
//                     X-Act-Token header or a token parameter; 403 without it
//
// No client can hold the e-stop up: it is served before routing, from its request line and headers
// (any body is never read), on its own connection thread, also when other clients hold every
// ordinary connection (past that, new connections serve only the e-stop). Connections that send
// nothing for 300 ms are closed, a request's head and body must arrive within 500 ms, bodies are
// at most 4 kB (413), at most 4 MJPEG streams (503). A command that moves the car and is more than
// 250 ms old, from when it reached the server or when the page issued it (X-Act-Issued), is
// refused (408). Every request but the e-stop needs a Host of this machine (an IP address,
// localhost, the --http name or this host's name; else 403: DNS rebinding), and every state change
// a same-origin Origin when it has one (403: a form on another site). Every error has a JSON body
// saying why.
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
  /// Before routing, so before any body is read: the e-stop (open to all, on its request line and
  /// headers alone), then the Host and Origin checks; and httplib's own refusals with a reason.
  void add_guards(Cockpit& cockpit);
  /// The page, the stats and the model's view (frame and MJPEG stream): anyone may read them.
  void add_view_routes(Cockpit& cockpit, const FrameSource& frames);
  /// Resume, mode and manual driving: the token only, and never late (the e-stop is a guard).
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
