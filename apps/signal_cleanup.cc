#include "apps/signal_cleanup.h"

#include <limits.h>
#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <cstring>
#include <mutex>

namespace act {

namespace {

constexpr int kSlots = 32;

struct Slot {
  std::atomic<bool> active{false};
  std::atomic<unsigned> order{0};
  bool is_dir = false;
  char path[PATH_MAX] = {};
};

Slot g_slots[kSlots];
std::atomic<unsigned> g_order{1};
std::mutex g_register_mutex;  // registration only; the handler never locks

extern "C" void cleanup_and_reraise(int sig) {
  // Newest first: repeatedly take the active slot with the largest order.
  bool done[kSlots] = {};
  for (int pass = 0; pass < kSlots; ++pass) {
    int best = -1;
    unsigned best_order = 0;
    for (int i = 0; i < kSlots; ++i) {
      if (!done[i] && g_slots[i].active.load() && g_slots[i].order.load() > best_order) {
        best = i;
        best_order = g_slots[i].order.load();
      }
    }
    if (best < 0) break;
    done[best] = true;
    if (g_slots[best].is_dir) {
      ::rmdir(g_slots[best].path);
    } else {
      ::unlink(g_slots[best].path);
    }
  }
  ::signal(sig, SIG_DFL);
  ::raise(sig);
}

}  // namespace

void install_signal_cleanup() {
  static std::once_flag once;
  std::call_once(once, [] {
    for (int sig : {SIGINT, SIGTERM, SIGHUP}) {
      struct sigaction sa {};
      sa.sa_handler = cleanup_and_reraise;
      sigemptyset(&sa.sa_mask);
      ::sigaction(sig, &sa, nullptr);
    }
  });
}

SignalCleanup::SignalCleanup(const std::string& path, bool is_dir) {
  if (path.size() >= PATH_MAX) return;
  std::lock_guard<std::mutex> lock(g_register_mutex);
  for (int i = 0; i < kSlots; ++i) {
    if (g_slots[i].active.load()) continue;
    std::memcpy(g_slots[i].path, path.c_str(), path.size() + 1);
    g_slots[i].is_dir = is_dir;
    g_slots[i].order.store(g_order.fetch_add(1));
    g_slots[i].active.store(true);
    slot_ = i;
    return;
  }
}

SignalCleanup::~SignalCleanup() { release(); }

void SignalCleanup::release() {
  if (slot_ >= 0) g_slots[slot_].active.store(false);
  slot_ = -1;
}

}  // namespace act
