#include "apps/drive/emergency_neutral.h"

#include <unistd.h>

#include <atomic>
#include <cstring>

#include "actengine/status.h"

namespace act::drive {
namespace {

struct Slot {
  int fd = -1;
  char bytes[kMaxEmergencyBytes];
  size_t length = 0;
};

// The handler reads g_armed first: slots are filled while it is 0 and published by storing the count.
Slot g_slots[kMaxEmergencyWrites];
std::atomic<size_t> g_armed{0};
static_assert(std::atomic<size_t>::is_always_lock_free, "a signal handler reads the count");

}  // namespace

void arm_emergency_writes(std::span<const EmergencyWrite> writes) {
  check(writes.size() <= kMaxEmergencyWrites, StatusCode::kInternal, "too many emergency writes");
  g_armed.store(0);
  for (size_t i = 0; i < writes.size(); ++i) {
    check(writes[i].bytes.size() <= kMaxEmergencyBytes, StatusCode::kInternal, "emergency write too long");
    std::memcpy(g_slots[i].bytes, writes[i].bytes.data(), writes[i].bytes.size());
    g_slots[i].length = writes[i].bytes.size();
    g_slots[i].fd = writes[i].fd;
  }
  g_armed.store(writes.size());
}

void disarm_emergency_writes() noexcept { g_armed.store(0); }

void emergency_neutral() noexcept {
  const size_t armed = g_armed.load();
  for (size_t i = 0; i < armed; ++i) {
    const ssize_t ignored = ::write(g_slots[i].fd, g_slots[i].bytes, g_slots[i].length);
    (void)ignored;
  }
}

}  // namespace act::drive
