// The last words of a dying act_drive: byte strings prepared in advance for the open actuator
// (a protocol line for the serial board, the neutral duty cycles for PWM channels) that a
// fatal-signal handler writes with nothing but write(2). The link that owns the descriptors arms
// them once it is ready and disarms them before it closes them.
#pragma once

#include <span>
#include <string_view>

namespace act::drive {

struct EmergencyWrite {
  int fd = -1;
  std::string_view bytes;  ///< copied when armed; at most kMaxEmergencyBytes
};

inline constexpr size_t kMaxEmergencyWrites = 2;
inline constexpr size_t kMaxEmergencyBytes = 48;

/// Replaces what emergency_neutral() writes. Not for signal handlers; `writes` must fit the limits.
void arm_emergency_writes(std::span<const EmergencyWrite> writes);
/// emergency_neutral() writes nothing until armed again.
void disarm_emergency_writes() noexcept;
/// Writes every armed string to its descriptor: async-signal-safe, for fatal-signal handlers.
void emergency_neutral() noexcept;

}  // namespace act::drive
