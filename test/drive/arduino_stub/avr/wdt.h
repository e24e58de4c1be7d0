// The AVR watchdog as the sketch uses it, recorded for the test (test/drive/test_sketch.cc).
#pragma once

#include <cstdint>

#define WDTO_15MS 0
#define WDTO_30MS 1
#define WDTO_60MS 2
#define WDTO_120MS 3
#define WDTO_250MS 4
#define WDTO_500MS 5
#define WDTO_1S 6

namespace arduino_stub {
inline int wdt_timeout = -1;  ///< the WDTO_ code enabled, -1 = off
inline uint32_t wdt_resets = 0;
inline uint32_t wdt_last_reset_ms = 0;
/// The enabled timeout in milliseconds (the WDTO_ codes double from 15 ms), -1 when off.
inline int wdt_timeout_ms() { return wdt_timeout < 0 ? -1 : 15 << wdt_timeout; }
}  // namespace arduino_stub

inline void wdt_enable(uint8_t timeout) { arduino_stub::wdt_timeout = timeout; }
inline void wdt_disable() { arduino_stub::wdt_timeout = -1; }
// millis() is declared by Arduino.h, which the sketch includes first.
inline void wdt_reset() {
  ++arduino_stub::wdt_resets;
  arduino_stub::wdt_last_reset_ms = arduino_stub::now_ms;
}
